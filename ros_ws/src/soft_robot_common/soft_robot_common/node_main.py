"""Declared, read-only parameters and a ``main()`` with clean shutdown for every node.

Each node module keeps a table ``[(name, default, description), ...]``, calls
:func:`declare_parameters` in ``__init__`` and raises :class:`ConfigurationError` for a
value it cannot work with; its ``main`` is ``run_node(NodeClass, args)``.
"""

from __future__ import annotations

import signal
import sys

import rclpy
from rcl_interfaces.msg import ParameterDescriptor, ParameterType
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException
from rclpy.signals import SignalHandlerOptions

_TYPES = {bool: ParameterType.PARAMETER_BOOL, int: ParameterType.PARAMETER_INTEGER,
          float: ParameterType.PARAMETER_DOUBLE, str: ParameterType.PARAMETER_STRING,
          list: ParameterType.PARAMETER_STRING_ARRAY}


class ConfigurationError(ValueError):
    """A parameter value that makes the node's job impossible (fatal at start-up: exit 2)."""


def declare_parameters(node, table, prefix: str = "") -> dict:
    """Declare ``(name, default, description)`` rows as typed read-only parameters.

    Returns ``{name: value}`` as set on the command line or in a parameter file. A value of
    the wrong type raises rclpy's ParameterException, which :func:`run_node` reports as a
    configuration error.
    """
    values = {}
    for name, default, description in table:
        ptype = _TYPES[type(default)]
        node.declare_parameter(prefix + name, default, ParameterDescriptor(
            type=ptype, description=description, read_only=True))
        values[name] = node.get_parameter(prefix + name).value
    return values


def _raise_keyboard_interrupt(signum, frame):
    raise KeyboardInterrupt(f"signal {signum}")


def run_node(node_class, args=None, close=None) -> int:
    """Create and spin ``node_class()`` until SIGINT/SIGTERM; return the exit code.

    SIGINT and SIGTERM are handled here rather than by rclpy (whose handler invalidates the
    context first), so a node can still log and publish while it shuts down. ``close``
    (optional) is called with the node before it is destroyed. A ConfigurationError or a
    wrongly typed parameter prints one line naming the problem and returns 2.
    """
    signal.signal(signal.SIGINT, _raise_keyboard_interrupt)
    signal.signal(signal.SIGTERM, _raise_keyboard_interrupt)
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    node = None
    try:
        node = node_class()
        rclpy.spin(node)
    except (ConfigurationError, ParameterException) as exc:
        name = getattr(node_class, "NODE_NAME", node_class.__name__)
        print(f"[{name}] fatal configuration error: {exc}", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            if close is not None:
                close(node)
            node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return 0
