"""One thread that owns a solver: requests queue in order, a newer target supersedes a pending one.

The kinematics node's ROS callbacks never solve: they hand work to a :class:`SolverWorker`
and (for services and actions) wait for its result on their own executor thread, so the
executor stays free for new requests, cancels and parameter calls. Work comes in two kinds:

* :meth:`SolverWorker.call` -- a request that must be answered (a service call, a whole
  trajectory); run in arrival order, the caller blocks until its result or exception;
* :meth:`SolverWorker.submit_latest` -- a command where only the newest matters (a streamed
  target): it replaces any pending one that has not started yet.

Calls go before a pending latest job. A long call (a trajectory) can let waiting calls run
between its steps with :meth:`SolverWorker.serve_pending` (from inside the call).
"""
from __future__ import annotations

import collections
import concurrent.futures
import threading
from typing import Callable, Optional


class SolverWorker:
    """A single worker thread (see module docstring).

    Parameters
    ----------
    on_error : callable, optional
        Called with the exception of a failed :meth:`submit_latest` job (calls re-raise in
        the caller instead).
    name : str
        Thread name.
    """

    def __init__(self, on_error: Optional[Callable[[BaseException], None]] = None, name: str = 'solver'):
        self._cond = threading.Condition()
        self._calls: collections.deque = collections.deque()
        self._latest: Optional[Callable] = None
        self._stopping = False
        self._busy = False
        self._on_error = on_error
        self.superseded = 0   #: latest jobs replaced before they started
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def call(self, fn: Callable, timeout: Optional[float] = None):
        """Run ``fn()`` on the worker (after the calls queued before it); return its result."""
        fut = concurrent.futures.Future()
        with self._cond:
            if self._stopping:
                raise RuntimeError("solver worker is stopped")
            self._calls.append((fn, fut))
            self._cond.notify()
        return fut.result(timeout)

    def submit_latest(self, fn: Callable) -> bool:
        """Queue ``fn()`` as the latest command; True if it superseded a pending one."""
        with self._cond:
            replaced = self._latest is not None
            if replaced:
                self.superseded += 1
            self._latest = fn
            self._cond.notify()
        return replaced

    @property
    def idle(self) -> bool:
        with self._cond:
            return not self._busy and not self._calls and self._latest is None

    def serve_pending(self) -> int:
        """Run the queued calls now (only from inside a job on the worker thread); return how many."""
        if threading.current_thread() is not self._thread:
            raise RuntimeError("serve_pending runs only on the worker thread")
        n = 0
        while True:
            with self._cond:
                if not self._calls:
                    return n
                fn, fut = self._calls.popleft()
            self._run_call(fn, fut)
            n += 1

    def stop(self, timeout: float = 5.0) -> None:
        """Finish the running job, fail queued calls, and end the thread."""
        with self._cond:
            self._stopping = True
            pending, self._calls = list(self._calls), collections.deque()
            self._latest = None
            self._cond.notify()
        for _, fut in pending:
            fut.set_exception(RuntimeError("solver worker stopped"))
        self._thread.join(timeout)

    @staticmethod
    def _run_call(fn, fut) -> None:
        if not fut.set_running_or_notify_cancel():
            return
        try:
            fut.set_result(fn())
        except BaseException as exc:  # handed to the caller, who reports it
            fut.set_exception(exc)

    def _run(self) -> None:
        while True:
            with self._cond:
                while not self._stopping and not self._calls and self._latest is None:
                    self._cond.wait()
                if self._stopping:
                    return
                self._busy = True
                if self._calls:
                    job = self._calls.popleft()
                    latest = None
                else:
                    job, latest, self._latest = None, self._latest, None
            try:
                if job is not None:
                    self._run_call(*job)
                else:
                    try:
                        latest()
                    except Exception as exc:
                        if self._on_error is not None:
                            self._on_error(exc)
            finally:
                with self._cond:
                    self._busy = False
