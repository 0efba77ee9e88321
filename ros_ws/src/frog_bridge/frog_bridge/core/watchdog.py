"""The bridge's own command watchdog: no primitive for a while means the planner is lost.

The planner publishes one primitive every period, I (no action) included, so a silence
longer than a few periods means it died, hangs or lost its link. The bridge then cancels
every pulse still pending (a rear pair of the last primitive, due one pulse after its front)
and reports it; a fresh primitive afterwards is accepted normally, since it is fresh.

The watchdog measures the time since the last primitive arrived (whether a primitive is
rests on a state too old to fire is the scheduler's check, ``max_state_age_s``). Times are seconds on
one clock chosen by the caller (the node's clock: simulated time in the twin, so a stalled
simulation does not trip it); when that clock goes back (a restarted simulator), the count
starts over.
"""

from __future__ import annotations

import math


class PrimitiveWatchdog:
    """Trips when no primitive has been seen for ``timeout_s``, once one had been.

    Parameters
    ----------
    timeout_s : float
        Longest silence [s], > 0.

    Examples
    --------
    >>> w = PrimitiveWatchdog(3.0)
    >>> w.check(10.0)                  # nothing seen yet: not armed
    False
    >>> w.fed(10.0)
    False
    >>> w.check(12.9), w.check(13.1), w.check(14.0)      # trips once
    (False, True, False)
    >>> w.tripped, w.fed(14.5), w.tripped               # a fresh primitive clears it
    (True, True, False)
    """

    def __init__(self, timeout_s: float):
        self.timeout_s = timeout_s
        self.last: float | None = None     # time of the newest primitive [s]
        self.tripped = False
        self.trips = 0

    @property
    def timeout_s(self) -> float:
        return self._timeout_s

    @timeout_s.setter
    def timeout_s(self, value: float) -> None:
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"primitive timeout {value!r} s must be a finite time > 0")
        self._timeout_s = float(value)

    def fed(self, now: float) -> bool:
        """A primitive arrived at ``now``; True if it clears a tripped watchdog (the planner is back)."""
        self.last = now
        was, self.tripped = self.tripped, False
        return was

    def silence(self, now: float) -> float | None:
        """Time since the last primitive arrived, at ``now`` [s]; None before the first."""
        return None if self.last is None else now - self.last

    def check(self, now: float) -> bool:
        """True exactly when the watchdog trips at ``now`` (cancel pending pulses then)."""
        if self.last is not None and now < self.last:      # the clock went back (a restarted simulation)
            self.last = now
        if self.tripped or self.last is None or now - self.last <= self.timeout_s:
            return False
        self.tripped = True
        self.trips += 1
        return True


def timeout_problem(timeout_s: float, rear_delay_s: float) -> str | None:
    """Why a watchdog ``timeout_s`` defeats the primitives it guards, or None.

    A primitive's rear pair is due ``rear_delay_s`` (one pulse) after its front pair; a
    watchdog no longer than that trips before every rear pair and cancels it, so a K or LR
    kick would fire its front limbs only. Cancelling fires nothing, so this is not unsafe, only
    useless: the caller warns and keeps the setting (a test may want exactly that).

    >>> timeout_problem(3.0, 0.08) is None
    True
    >>> timeout_problem(0.2, 0.5)[:68]
    'primitive_timeout_s 0.2 s is not longer than the front-to-rear delay'
    """
    if timeout_s > rear_delay_s:
        return None
    return (f"primitive_timeout_s {timeout_s:g} s is not longer than the front-to-rear delay {rear_delay_s:g} s "
            f"(pulse_ms): the watchdog will cancel the rear pair of every primitive")
