"""Supervision of a serial link to a device: state machine, reconnect backoff, line age.

States (:class:`LinkState`)::

    DISCONNECTED --opened--> CONNECTING --settled--> READY
         ^   ^                   |                     |
         |   +------lost---------+---------lost--------+
         +-- open_failed (retry after a backoff: period, 2x, 4x ... up to max_period)

    any state --emergency--> EMERGENCY (latched; reported above the connection state)
    EMERGENCY --clear_emergency--> the connection state underneath

CONNECTING lasts ``settle_s`` after the port opened (the frog authors' code waits after
opening before it writes ``p``; a dev-kit or an Arduino resets when its USB port is opened
and prints a banner), or until the node sees the device is up and calls ``ready``. Only
READY actuates. EMERGENCY is the device's own stop (the relay's emergency line, Marlin's
kill()). Times are seconds on a steady clock (the device runs in real time).
"""

from __future__ import annotations

import enum
import math


class LinkState(enum.Enum):
    DISCONNECTED = "disconnected"
    CONNECTING = "connecting"
    READY = "ready"
    EMERGENCY = "emergency"


class LinkSupervisor:
    """Pure state machine; the node does the I/O and reports what happened.

    Parameters
    ----------
    reconnect_period_s : float
        Delay before the first retry after a loss or a failed open [s].
    reconnect_max_period_s : float
        Cap of the doubling backoff [s] (>= ``reconnect_period_s``).
    settle_s : float
        Time between opening the port and writing to it [s].
    stall_timeout_s : float
        READY with no line from the relay for longer than this is reported as stalled
        (0 = never).
    """

    def __init__(self, reconnect_period_s: float = 0.5, reconnect_max_period_s: float = 5.0,
                 settle_s: float = 1.0, stall_timeout_s: float = 2.0):
        for name, v in (("reconnect_period_s", reconnect_period_s), ("settle_s", settle_s),
                        ("stall_timeout_s", stall_timeout_s)):
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} {v!r} must be >= 0")
        if not reconnect_max_period_s >= reconnect_period_s > 0:
            raise ValueError(f"need 0 < reconnect_period_s ({reconnect_period_s}) <= "
                             f"reconnect_max_period_s ({reconnect_max_period_s})")
        self.reconnect_period_s = reconnect_period_s
        self.reconnect_max_period_s = reconnect_max_period_s
        self.settle_s = settle_s
        self.stall_timeout_s = stall_timeout_s
        self.connection = LinkState.DISCONNECTED
        self.emergency_latched = False
        self.emergency_text = ""
        self.failures = 0                   # consecutive failed opens
        self.next_attempt = -math.inf       # first open right away
        self.opened_at: float | None = None
        self.last_line_at: float | None = None
        self.losses = 0
        self.last_problem = ""

    @property
    def state(self) -> LinkState:
        return LinkState.EMERGENCY if self.emergency_latched else self.connection

    @property
    def can_actuate(self) -> bool:
        return self.state is LinkState.READY

    def should_attempt(self, now: float) -> bool:
        return self.connection is LinkState.DISCONNECTED and now >= self.next_attempt

    def backoff(self) -> float:
        """Delay before the next attempt after ``failures`` consecutive failures."""
        n = max(self.failures - 1, 0)
        return min(self.reconnect_period_s * 2.0 ** min(n, 30), self.reconnect_max_period_s)

    def opened(self, now: float) -> None:
        self.connection = LinkState.CONNECTING
        self.opened_at = now
        self.last_line_at = None

    def open_failed(self, now: float, problem: str) -> None:
        self.failures += 1
        self.last_problem = problem
        self.next_attempt = now + self.backoff()

    def settled(self, now: float) -> bool:
        """True once CONNECTING has lasted ``settle_s`` (then write ``p`` and call ready)."""
        return (self.connection is LinkState.CONNECTING and self.opened_at is not None
                and now - self.opened_at >= self.settle_s)

    def ready(self, now: float) -> None:
        self.connection = LinkState.READY
        self.failures = 0

    def lost(self, now: float, problem: str) -> None:
        self.connection = LinkState.DISCONNECTED
        self.losses += 1
        self.failures = 1
        self.last_problem = problem
        self.next_attempt = now + self.reconnect_period_s
        self.opened_at = None

    def line_received(self, now: float) -> None:
        self.last_line_at = now

    def line_age(self, now: float) -> float | None:
        return None if self.last_line_at is None else now - self.last_line_at

    def stalled(self, now: float) -> bool:
        if self.stall_timeout_s <= 0 or self.connection is not LinkState.READY:
            return False
        since = self.last_line_at if self.last_line_at is not None else self.opened_at
        return since is not None and now - since > self.stall_timeout_s

    def emergency(self, text: str) -> bool:
        """Latch an emergency; True if it was not latched before."""
        new = not self.emergency_latched
        self.emergency_latched = True
        self.emergency_text = text
        return new

    def clear_emergency(self) -> bool:
        """Unlatch; True if there was an emergency to clear."""
        was = self.emergency_latched
        self.emergency_latched = False
        self.emergency_text = ""
        return was
