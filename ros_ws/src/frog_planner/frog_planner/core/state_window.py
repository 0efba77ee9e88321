"""The mean state of the poses received since the last decision (the paper's planner loop).

The authors' planner (their published control code) did not decide on the newest pose at the
period tick: a planner process averaged the states it polled from the tracker since its last
decision (nine, about 0.63 s of frames), decided on that mean and queued the result, and an
executor process sent the newest queued decision once a period. A decision therefore acted on a
state about 0.3-1.0 s old. :class:`StateWindow` holds that mean for ``planner_node
replan_interval``.
"""
from __future__ import annotations

import math

import numpy as np


class StateWindow:
    """Running mean of (pose, body twist) samples; the heading is unwrapped against the first.

    Examples
    --------
    >>> w = StateWindow()
    >>> w.add((0.0, 0.0, math.pi - 0.3), (0.02, 0.0, 0.1))
    >>> w.add((0.002, 0.0, -math.pi + 0.1), (0.04, 0.0, 0.3))
    >>> pose, twist, n = w.mean()
    >>> round(float(pose[2]), 6), round(float(twist[0]), 3), n
    (3.041593, 0.03, 2)
    """

    def __init__(self):
        self.clear()

    def clear(self) -> None:
        """Forget the samples (after a decision)."""
        self._sum = np.zeros(6)
        self._first_heading = None
        self.count = 0

    def add(self, pose, twist) -> None:
        """One sample: pose (x m, y m, heading rad, any wrapping), body twist (u, v m/s, r rad/s)."""
        x, y, h = (float(v) for v in pose)
        if self._first_heading is None:
            self._first_heading = h
        h = self._first_heading + math.remainder(h - self._first_heading, 2 * math.pi)
        self._sum += (x, y, h, *(float(v) for v in twist))
        self.count += 1

    def mean(self):
        """(pose (3,), twist (3,), count); the heading wrapped to [-pi, pi]. Raises if empty."""
        if self.count == 0:
            raise ValueError("no state received since the last decision")
        m = self._sum / self.count
        m[2] = math.remainder(m[2], 2 * math.pi)
        return m[:3], m[3:], self.count
