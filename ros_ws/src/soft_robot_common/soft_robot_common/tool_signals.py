"""Signals that end a tool which started node processes, so that it stops them first.

The nodes run in their own sessions (a terminal's Ctrl-C reaches only the tool), so they
stop only when the tool stops them. Python's default SIGTERM and SIGHUP end a process
without running its ``finally`` blocks: a ``kill``, ``timeout`` or a closed terminal
would leave the planner and the bridge running on their own. Here they end the tool as
Ctrl-C does.
"""

from __future__ import annotations

import signal
from contextlib import contextmanager

#: the signals that ask a tool to stop (SIGINT: Ctrl-C; SIGTERM: kill, timeout; SIGHUP: terminal closed)
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


class _Deferred:
    """A stop that came while rclpy was converting a message: raised there, it would come out
    of the executor as an unrelated RuntimeError, so it is raised when rclpy returns."""

    depth = 0
    pending = None


def _interrupt(signum, frame):
    if _Deferred.depth:
        _Deferred.pending = stop_name(signum)
        return
    raise KeyboardInterrupt(stop_name(signum))


@contextmanager
def rclpy_call():
    """Around an executor's ``spin_once``: a stop signal within it is raised after it."""
    _Deferred.depth += 1
    try:
        yield
    finally:
        _Deferred.depth -= 1
        if not _Deferred.depth and _Deferred.pending is not None:
            pending, _Deferred.pending = _Deferred.pending, None
            raise KeyboardInterrupt(pending)


def stop_on_signals():
    """SIGTERM and SIGHUP raise :class:`KeyboardInterrupt`, as SIGINT does; returns the undo.

    :class:`~soft_robot_common.graph_watch.GraphWatch` installs no rclpy handler, and its
    spins defer a stop to their end (:func:`rclpy_call`).
    """
    return _install(_interrupt)


def _install(handler):
    previous = {sig: signal.signal(sig, handler) for sig in STOP_SIGNALS}

    def restore():
        for sig, old in previous.items():
            signal.signal(sig, old)
    return restore


def stop_name(signum) -> str:
    """How a stop signal is named in a stop reason."""
    return "Ctrl-C" if signum == signal.SIGINT else signal.Signals(signum).name


def redirect_stop_signals(callback):
    """Every stop signal calls ``callback(stop_name)`` instead (a graceful stop); returns the undo."""
    return _install(lambda signum, frame: callback(stop_name(signum)))
