"""A ``main()`` with clean shutdown, configuration errors and start-up checks for every node.

Each node module declares its parameters with :func:`soft_robot_common.declare_parameters`,
raises :class:`ConfigurationError` for a value it cannot work with, and its ``main`` is
``run_node(NodeClass, args)``.
"""

from __future__ import annotations

import ctypes
import faulthandler
import os
import signal
import sys
import threading
import time

import rclpy
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.signals import SignalHandlerOptions

from .clock_watch import SimClockWatch
from .parameters import ConfigurationError, undeclared_overrides
from .processes import MIDDLEWARE_TEARDOWN_S, PARENT_PID_ENV

PR_SET_PDEATHSIG = 1     # <linux/prctl.h>
# A spin loop that has not come back for this long (a callback blocked in the middleware, or the
# teardown: executor shutdown, close, destroy_node) dumps every thread's traceback to stderr (the
# node's log), from faulthandler's own thread, so a hang is diagnosable even inside C. Below
# NodeProcess.stop's 10 s wait for SIGINT, so the dump is written before the escalation.
STUCK_DUMP_S = 8.0
# After MIDDLEWARE_TEARDOWN_S of destroy_node (a node's own clean-up there, e.g. a worker's 5 s
# stop, then the middleware's) and rclpy.shutdown the process exits without them, saying where
# they were: Fast DDS can block for good deleting an image publisher whose reliable subscriber was
# SIGKILLed (camera_sim, docs/faults.md). close() has run by then.


class _StopRequest:
    """Set by SIGINT/SIGTERM; the spin loop checks it between executor wake-ups.

    A handler that raised (KeyboardInterrupt) could interrupt rclpy inside a C++ call (a
    message being converted) and surface as an unrelated RuntimeError; a flag cannot. While
    the node is being constructed (loading meshes, compiling kernels: up to a minute)
    nothing reads the flag, so until :attr:`starting` is cleared a signal also raises
    :class:`KeyboardInterrupt`, which ends the start-up at once. Raised inside a callback
    from C (llvmlite's object cache while numba compiles) the exception is printed and
    dropped, so the raise is repeated every :attr:`REPEAT_S` (SIGALRM) until the start-up
    has ended; after :attr:`MAX_DROPPED` dropped raises the process exits at once (exit
    code 0: nothing was running yet).
    """

    REPEAT_S = 0.2
    MAX_DROPPED = 5

    def __init__(self, name: str = "node"):
        self.signal = None
        self.starting = True
        self.name = name
        self.dropped = 0
        self._hook = None

    def __call__(self, signum, frame):
        if signum != getattr(signal, "SIGALRM", None):
            self.signal = signum
        if self.starting and self.signal is not None:
            if hasattr(signal, "setitimer"):
                signal.signal(signal.SIGALRM, self)
                signal.setitimer(signal.ITIMER_REAL, self.REPEAT_S, self.REPEAT_S)
            if self._hook is None:
                self._hook = sys.unraisablehook
                sys.unraisablehook = self._unraisable
            raise KeyboardInterrupt

    def _unraisable(self, info) -> None:
        """A KeyboardInterrupt that a callback from C dropped: count it; give up waiting after a few."""
        self._hook(info)
        if self.starting and isinstance(info.exc_value, KeyboardInterrupt):
            self.dropped += 1
            if self.dropped >= self.MAX_DROPPED:
                print(f"[{self.name}] stopped by signal during start-up", file=sys.stderr, flush=True)
                os._exit(0)

    def started(self) -> None:
        """The node exists: the spin loop reads the flag from now on."""
        self.starting = False
        self.disarm()

    def disarm(self) -> None:
        if hasattr(signal, "setitimer"):
            signal.setitimer(signal.ITIMER_REAL, 0)
        if self._hook is not None:
            sys.unraisablehook, self._hook = self._hook, None


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


def stop_with_parent() -> None:
    """A node started by one of our tools (``NodeProcess``) gets SIGTERM when the tool dies.

    The tool stops its nodes itself; this is for when it cannot (SIGKILL, a crash), so that
    no planner or bridge goes on alone. Linux only (prctl); the signal comes when the thread
    that started the node ends, and all our tools start nodes from their main thread.
    """
    parent = os.environ.get(PARENT_PID_ENV, "")
    if not (parent.isdigit() and sys.platform.startswith("linux")):
        return
    ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0)
    try:
        os.kill(int(parent), 0)
    except ProcessLookupError:       # it died before the prctl
        os.kill(os.getpid(), signal.SIGTERM)
    except PermissionError:          # alive, another user's
        pass


def run_node(node_class, args=None, close=None, executor=None) -> int:
    """Create and spin ``node_class()`` until SIGINT/SIGTERM; return the exit code.

    SIGINT and SIGTERM are handled here rather than by rclpy (whose handler invalidates the
    context first), so a node can still log and publish while it shuts down. ``close``
    (optional) is called with the node before it is destroyed. A ConfigurationError or a
    wrongly typed parameter prints one line naming the problem and returns 2. ``executor``
    (optional) makes the executor to spin with after ``rclpy.init`` (a class or factory,
    e.g. ``MultiThreadedExecutor`` for a node that serves requests while a long solve runs).
    """
    stop = _StopRequest(_name(node_class, args))
    signal.signal(signal.SIGINT, stop)
    signal.signal(signal.SIGTERM, stop)
    stop_with_parent()
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    node = None
    spinner = None
    code = 0
    try:
        if stop.signal is not None:      # a signal before the handler could raise
            raise KeyboardInterrupt
        node = node_class()
        stop.started()
        for name, hint in undeclared_overrides(node):
            node.get_logger().warn(f"parameter override '{name}' is not a parameter of this node and is ignored"
                                   + (f" (did you mean '{hint}'?)" if hint else ""))
        if SimClockWatch.wanted(node):
            node._sim_clock_watch = SimClockWatch(node)
        spinner = executor() if executor is not None else SingleThreadedExecutor()
        spinner.add_node(node)
        # wake-ups at least every 0.1 s, so a stop request is seen even in a node without timers
        armed = -1.0
        while stop.signal is None and rclpy.ok():
            if time.monotonic() - armed >= STUCK_DUMP_S / 8:     # re-armed often: fires only if stuck
                faulthandler.dump_traceback_later(STUCK_DUMP_S, exit=False)
                armed = time.monotonic()
            spinner.spin_once(timeout_sec=0.1)
    except (ConfigurationError, ParameterException) as exc:
        name = node.get_logger().name if node is not None else _name(node_class, args)
        print(f"[{name}] fatal configuration error: {exc}", file=sys.stderr)
        code = 2
        return code
    except (KeyboardInterrupt, ExternalShutdownException):
        if node is None:
            print(f"[{_name(node_class, args)}] stopped by signal during start-up", file=sys.stderr)
    finally:
        stop.starting = False
        stop.disarm()
        faulthandler.dump_traceback_later(STUCK_DUMP_S, exit=False)
        try:
            if spinner is not None:
                spinner.shutdown(timeout_sec=5.0)
            if node is not None and close is not None:
                close(node)
            give_up = threading.Timer(MIDDLEWARE_TEARDOWN_S, _exit_without_teardown,
                                      args=(_name(node_class, args), lambda: code))
            give_up.daemon = True
            give_up.start()
            if node is not None:
                node.destroy_node()
            if rclpy.ok():
                rclpy.shutdown()
            give_up.cancel()
        finally:
            faulthandler.cancel_dump_traceback_later()
    return code


def _exit_without_teardown(name: str, code) -> None:
    """The middleware's teardown is blocked: say where, and end the process without it."""
    print(f"[{name}] the middleware's teardown (destroy_node, rclpy.shutdown) is still blocked after "
          f"{MIDDLEWARE_TEARDOWN_S:g} s; exiting without it. Where it is:", file=sys.stderr, flush=True)
    faulthandler.dump_traceback(all_threads=True)
    sys.stdout.flush()
    os._exit(code())
