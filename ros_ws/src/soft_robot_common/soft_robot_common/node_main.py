"""A ``main()`` with clean shutdown, configuration errors and start-up checks for every node.

Each node module declares its parameters with :func:`soft_robot_common.declare_parameters`,
raises :class:`ConfigurationError` for a value it cannot work with, and its ``main`` is
``run_node(NodeClass, args)``.
"""

from __future__ import annotations

import signal
import sys

import rclpy
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.signals import SignalHandlerOptions

from .clock_watch import SimClockWatch
from .parameters import ConfigurationError, undeclared_overrides


class _StopRequest:
    """Set by SIGINT/SIGTERM; the spin loop checks it between executor wake-ups.

    A handler that raised (KeyboardInterrupt) could interrupt rclpy inside a C++ call (a
    message being converted) and surface as an unrelated RuntimeError; a flag cannot. While
    the node is being constructed (loading meshes, compiling kernels: up to a minute)
    nothing reads the flag, so until :attr:`starting` is cleared a signal also raises
    :class:`KeyboardInterrupt`, which ends the start-up at once.
    """

    def __init__(self):
        self.signal = None
        self.starting = True

    def __call__(self, signum, frame):
        self.signal = signum
        if self.starting:
            raise KeyboardInterrupt


def _name(node_class, args=None) -> str:
    """The node's logger name (``ns.name``) as ``--ros-args -r __node:=`` / ``__ns:=`` set it.

    For messages printed when the node could not be constructed (no logger to ask).
    """
    name = getattr(node_class, "NODE_NAME", node_class.__name__)
    namespace = ""
    argv = list(sys.argv[1:] if args is None else args)
    for i, arg in enumerate(argv):
        rule = argv[i + 1] if arg in ("-r", "--remap") and i + 1 < len(argv) else None
        if rule is None:
            continue
        target, _, value = rule.partition(":=")
        owner, _, key = target.rpartition(":")
        if owner and owner != name:
            continue
        if key == "__node":
            name = value
        elif key == "__ns":
            namespace = value
    parts = [p for p in namespace.split("/") if p]
    return ".".join(parts + [name])


def run_node(node_class, args=None, close=None, executor=None) -> int:
    """Create and spin ``node_class()`` until SIGINT/SIGTERM; return the exit code.

    SIGINT and SIGTERM are handled here rather than by rclpy (whose handler invalidates the
    context first), so a node can still log and publish while it shuts down. ``close``
    (optional) is called with the node before it is destroyed. A ConfigurationError or a
    wrongly typed parameter prints one line naming the problem and returns 2. ``executor``
    (optional) makes the executor to spin with after ``rclpy.init`` (a class or factory,
    e.g. ``MultiThreadedExecutor`` for a node that serves requests while a long solve runs).
    """
    stop = _StopRequest()
    signal.signal(signal.SIGINT, stop)
    signal.signal(signal.SIGTERM, stop)
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    node = None
    spinner = None
    try:
        if stop.signal is not None:      # a signal before the handler could raise
            raise KeyboardInterrupt
        node = node_class()
        stop.starting = False
        for name, hint in undeclared_overrides(node):
            node.get_logger().warn(f"parameter override '{name}' is not a parameter of this node and is ignored"
                                   + (f" (did you mean '{hint}'?)" if hint else ""))
        if SimClockWatch.wanted(node):
            node._sim_clock_watch = SimClockWatch(node)
        spinner = executor() if executor is not None else SingleThreadedExecutor()
        spinner.add_node(node)
        # wake-ups at least every 0.1 s, so a stop request is seen even in a node without timers
        while stop.signal is None and rclpy.ok():
            spinner.spin_once(timeout_sec=0.1)
    except (ConfigurationError, ParameterException) as exc:
        name = node.get_logger().name if node is not None else _name(node_class, args)
        print(f"[{name}] fatal configuration error: {exc}", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, ExternalShutdownException):
        if node is None:
            print(f"[{_name(node_class, args)}] stopped by signal during start-up", file=sys.stderr)
    finally:
        if spinner is not None:
            spinner.shutdown(timeout_sec=5.0)
        if node is not None:
            if close is not None:
                close(node)
            node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return 0
