"""The serial device in a thread of its own: open, read, reconnect with backoff, close.

One design for every serial node (the frog's relay bridge, the finger's Marlin driver).
:class:`SerialLink` owns the file descriptor: only its thread opens and closes the port
(so no other thread can ever read a reused descriptor number). Other threads write whole
lines with :meth:`SerialLink.write_line` and receive what happened through ``on_event``
(called from the link thread); :meth:`SerialLink.for_node` wires that to a ROS guard
condition, so the node's protocol logic runs in its executor. The link's state machine is a
:class:`~soft_robot_common.link_state.LinkSupervisor`; nodes read it through
:meth:`SerialLink.snapshot` and change it through the link's methods, which take
:attr:`SerialLink.lock`. Times are ``time.monotonic()`` seconds.
"""

from __future__ import annotations

import os
import select
import threading
import time
from collections import deque
from dataclasses import dataclass
from typing import Callable

import serial

from .link_state import LinkState, LinkSupervisor


@dataclass(frozen=True)
class LinkEvent:
    """``kind``: "data" (``data`` bytes), "opened", "lost", "open_failed" (``text`` says why)."""

    kind: str
    at: float
    data: bytes = b""
    text: str = ""


@dataclass(frozen=True)
class LinkSnapshot:
    """The link's state at one instant, read under the lock (for decisions and diagnostics)."""

    state: LinkState
    stalled: bool
    line_age: float | None     # seconds since the last line, None before the first
    last_problem: str
    losses: int
    emergency_text: str
    bytes_read: int
    bytes_written: int


class SerialLink:
    """Keep a serial device open, reading in a thread, reopening it after a loss.

    Parameters
    ----------
    path : str
        Device path (e.g. ``/dev/ttyACM0``, or a pty link).
    baud : int
        Baud rate.
    supervisor : LinkSupervisor
        Reconnect periods and state; updated by this class under :attr:`lock`.
    on_event : callable
        ``on_event()`` is called (from the link thread) after events were queued; fetch
        them with :meth:`events`.
    write_timeout_s : float
        A write that cannot complete within this is a lost link.
    """

    def __init__(self, path: str, baud: int, supervisor: LinkSupervisor, on_event: Callable[[], None],
                 write_timeout_s: float = 0.05):
        self.path = path
        self.baud = baud
        self.supervisor = supervisor
        self.on_event = on_event
        self.write_timeout_s = write_timeout_s
        self.lock = threading.Lock()
        self._port: serial.Serial | None = None
        self._events: deque[LinkEvent] = deque()
        self._wake_r, self._wake_w = os.pipe()
        self._close_reason: str | None = None
        self._running = True
        self.bytes_read = 0
        self.bytes_written = 0
        self._thread = threading.Thread(target=self._run, name="serial_link", daemon=True)

    @classmethod
    def for_node(cls, node, on_events: Callable[[], None], path: str, baud: int, supervisor: LinkSupervisor,
                 write_timeout_s: float = 0.05) -> "SerialLink":
        """A link whose events wake ``node``'s executor: ``on_events()`` runs there (call :meth:`events`)."""
        wake = node.create_guard_condition(on_events)
        link = cls(path, baud, supervisor, wake.trigger, write_timeout_s)
        link.guard = wake          # the node owns it; keep it alive as long as the link
        return link

    def start(self) -> None:
        self._thread.start()

    # -- the state machine, under the lock ------------------------------------------------
    def snapshot(self, now: float | None = None) -> LinkSnapshot:
        now = time.monotonic() if now is None else now
        with self.lock:
            s = self.supervisor
            return LinkSnapshot(s.state, s.stalled(now), s.line_age(now), s.last_problem, s.losses,
                                s.emergency_text, self.bytes_read, self.bytes_written)

    def settled(self, now: float) -> bool:
        """Opened and settled: the node initialises the device, then calls :meth:`ready`."""
        with self.lock:
            return self.supervisor.settled(now)

    def connecting_since(self) -> float | None:
        """When the port opened while CONNECTING, else None."""
        with self.lock:
            s = self.supervisor
            return s.opened_at if s.connection is LinkState.CONNECTING else None

    def ready(self, now: float) -> None:
        with self.lock:
            self.supervisor.ready(now)

    def line_received(self, at: float) -> None:
        with self.lock:
            self.supervisor.line_received(at)

    def emergency(self, text: str) -> bool:
        """Latch an emergency (nothing actuates); True if it was not latched before."""
        with self.lock:
            return self.supervisor.emergency(text)

    def clear_emergency(self) -> bool:
        with self.lock:
            return self.supervisor.clear_emergency()

    # -- called from other threads ------------------------------------------------------
    def events(self) -> list[LinkEvent]:
        out = []
        while self._events:
            out.append(self._events.popleft())
        return out

    def write_line(self, line: bytes) -> str | None:
        """Write one whole line; None on success, else why it failed (the link is then lost)."""
        with self.lock:
            port = self._port
            if port is None or self.supervisor.connection is LinkState.DISCONNECTED:
                return "port is not open"
            try:
                # pyserial writes straight to the descriptor; no flush(): that is tcdrain(), which
                # would block the caller for the whole transmission on a real UART
                n = port.write(line)
            except (serial.SerialException, OSError) as exc:   # includes SerialTimeoutException
                problem = f"write failed: {exc}"
            else:
                if n == len(line):
                    self.bytes_written += n
                    return None
                problem = f"write incomplete ({n} of {len(line)} bytes)"
        self.request_close(problem)
        return problem

    def request_close(self, reason: str) -> None:
        """Ask the link thread to close the port and treat the link as lost."""
        self._close_reason = reason
        os.write(self._wake_w, b"c")

    def stop(self, timeout: float = 2.0) -> None:
        """Stop the thread and close the port (after pending writes: they hold the lock)."""
        self._running = False
        try:
            os.write(self._wake_w, b"s")
        except OSError:
            pass
        self._thread.join(timeout)
        with self.lock:
            self._close_port()
        for fd in (self._wake_r, self._wake_w):
            try:
                os.close(fd)
            except OSError:
                pass

    # -- the link thread ------------------------------------------------------------------
    def _emit(self, event: LinkEvent) -> None:
        self._events.append(event)
        self.on_event()

    def _close_port(self) -> None:
        port, self._port = self._port, None
        if port is not None:
            try:
                port.close()
            except (serial.SerialException, OSError):
                pass

    def _lose(self, problem: str) -> None:
        now = time.monotonic()
        with self.lock:
            self._close_port()
            self.supervisor.lost(now, problem)
        self._emit(LinkEvent("lost", now, text=problem))

    def _open(self) -> None:
        now = time.monotonic()
        try:
            port = serial.Serial(port=self.path, baudrate=self.baud, timeout=0,
                                 write_timeout=self.write_timeout_s, exclusive=True)
            port.reset_input_buffer()        # bytes from before this open are stale
        except (serial.SerialException, OSError, ValueError) as exc:
            with self.lock:
                self.supervisor.open_failed(now, str(exc))
            self._emit(LinkEvent("open_failed", now, text=str(exc)))
            return
        with self.lock:
            self._port = port
            self.supervisor.opened(now)
        self._emit(LinkEvent("opened", now, text=self.path))

    def _drain_wake(self) -> None:
        try:
            os.read(self._wake_r, 4096)
        except OSError:
            pass

    def _run(self) -> None:
        while self._running:
            with self.lock:
                port = self._port
                attempt = self.supervisor.should_attempt(time.monotonic())
                wait = max(0.0, self.supervisor.next_attempt - time.monotonic())
            if port is None:
                if attempt:
                    self._open()
                    continue
                ready, _, _ = select.select([self._wake_r], [], [], min(wait, 0.2))
                if ready:
                    self._drain_wake()
                continue
            try:
                ready, _, _ = select.select([port.fileno(), self._wake_r], [], [], 0.2)
            except (OSError, ValueError) as exc:
                self._lose(f"select failed: {exc}")
                continue
            if self._wake_r in ready:
                self._drain_wake()
                if self._close_reason is not None:
                    reason, self._close_reason = self._close_reason, None
                    self._lose(reason)
                    continue
            if port.fileno() in ready:
                try:
                    data = os.read(port.fileno(), 65536)
                except OSError as exc:
                    self._lose(f"read failed: {exc.strerror or exc}")
                    continue
                if not data:
                    self._lose("device closed (end of file)")
                    continue
                self.bytes_read += len(data)
                self._emit(LinkEvent("data", time.monotonic(), data=data))
