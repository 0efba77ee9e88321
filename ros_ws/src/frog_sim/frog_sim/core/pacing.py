"""Pacing a simulation against the wall clock: the simulated time to step to now.

A real-time world that falls behind a little (a slow tick, a busy machine) catches up. One that
falls behind by more than ``max_lag_s`` of wall time (its process starved, or blocked in the
middleware: a CI run's ``sim_node`` stood 2.5 s in ``publish`` after another node was
SIGKILLed, docs/faults.md) drops that lag and continues from where it is at the real-time
factor, as the robot's world would. Catching it up instead raced 3.4 s of simulated time
through 0.2 s of wall time: every node on ``/clock`` saw a burst of decisions and firings, and
every wall-clock process (discovery, serial links) saw seconds of world pass in an instant.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass
class Pacer:
    """Simulated time against wall time, from an anchor, less the lag dropped since it.

    ``rtf``: simulated seconds per wall second (0: as fast as possible, never behind).
    ``max_lag_s``: wall seconds the simulation may be behind and still catch up (0: always catch up).
    """

    rtf: float
    max_lag_s: float
    wall_start: float = 0.0
    sim_start: float = 0.0
    dropped_s: float = 0.0      # simulated seconds dropped since the anchor
    drops: int = 0              # times a lag was dropped (since the node started)
    dropped_total_s: float = 0.0

    def __post_init__(self):
        if not (self.rtf >= 0 and self.max_lag_s >= 0 and math.isfinite(self.rtf) and math.isfinite(self.max_lag_s)):
            raise ValueError(f"pacing: need finite real_time_factor >= 0 and max_lag_s >= 0, got {self.rtf}, "
                             f"{self.max_lag_s}")

    def anchor(self, wall: float, sim: float) -> None:
        """Pace from here (a new rate, a resume, a reset): no jump either way."""
        self.wall_start, self.sim_start, self.dropped_s = wall, sim, 0.0

    def target(self, wall: float, sim: float) -> tuple[float, float]:
        """(simulated time to step to, simulated seconds of lag dropped now: 0.0 if none)."""
        if self.rtf == 0:
            return math.inf, 0.0
        target = self.sim_start + (wall - self.wall_start) * self.rtf - self.dropped_s
        lag = target - sim
        if self.max_lag_s > 0 and lag > self.max_lag_s * self.rtf:
            self.dropped_s += lag
            self.drops += 1
            self.dropped_total_s += lag
            return sim, lag
        return target, 0.0

    def achieved_rtf(self, wall: float, sim: float) -> float:
        """Simulated over wall seconds since the anchor (a dropped lag lowers it: time the world lost)."""
        elapsed = wall - self.wall_start
        return (sim - self.sim_start) / elapsed if elapsed > 0 else math.nan
