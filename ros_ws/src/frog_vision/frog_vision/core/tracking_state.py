"""The tracker's states over a stream of frames: searching, tracking, coasting, lost, frozen.

:class:`TrackingStates` is what ``tracker_node`` knows between frames, without ROS: whether a
frame may be used at all (its stamp must advance; a copy of the previous picture holds no
new observation, and a run of ``frozen_frames`` copies means a frozen camera), the state
after each frame the tracker processed, the capture stamp of the newest frame in which the
tag was seen (the *state stamp* every pose carries to the planner, also while it is a
prediction), and the figures of the node's diagnostics. Times are capture stamps [s].

The state codes are ``soft_robot_interfaces/TrackerState``'s (checked by the package's tests).
"""
from __future__ import annotations

import collections
import math
from dataclasses import dataclass

import numpy as np

from frog_vision.core.frame_check import FrozenFrameDetector

SEARCHING, TRACKING, COASTING, LOST, FROZEN = range(5)
STATE_NAMES = ("searching", "tracking", "coasting", "lost", "frozen")
#: diagnostics levels (diagnostic_msgs/DiagnosticStatus)
OK, WARN, ERROR = 0, 1, 2


@dataclass(frozen=True)
class Change:
    """Something worth a log line: a change of state (``warn`` for trouble, else info), or a refused
    frame (``error``)."""

    state: int | None
    text: str
    warn: bool = False
    error: bool = False


class TrackingStates:
    """Frame admission, state, state stamp and diagnostics of one tracker (see the module docstring).

    Parameters
    ----------
    frozen_frames : int
        Byte-identical frames in a row (the first included) that mean a frozen camera, >= 2.
    window : int
        Frames the diagnostics' rates and medians are taken over.

    Examples
    --------
    >>> t = TrackingStates(frozen_frames=3)
    >>> t.admit(0.0, b"a")[0], t.processed(0.0, seen=True, publishing=True).text
    ('use', 'tag tracking')
    >>> t.admit(0.033, b"b")[0], t.processed(0.033, seen=False, publishing=True, coasting=True).text
    ('use', 'tag coasting')
    >>> t.state_name, t.state_stamp
    ('coasting', 0.0)
    """

    def __init__(self, frozen_frames: int = 3, window: int = 90):
        self.frozen = FrozenFrameDetector(frozen_frames)
        self.state: int | None = None         # None until the first frame is processed
        self.state_stamp: float | None = None  # newest capture stamp with the tag seen
        self.ever_seen = False
        self.last_stamp: float | None = None
        self.period: float | None = None       # smoothed frame interval [s]
        self.frames = self.dropped = self.bad_frames = self.repeated_skipped = 0
        self.last_error = ""
        self._logged_error: str | None = None
        self._before_freeze: int | None = None
        self._frozen_refused = 0
        self._window = collections.deque(maxlen=window)   # (seen, latency s, compute s, residual px)

    @property
    def state_name(self) -> str:
        return "waiting for images" if self.state is None else STATE_NAMES[self.state]

    # -- frames in -------------------------------------------------------------------------
    def admit(self, stamp: float, data) -> tuple[str, Change | None]:
        """What to do with the frame captured at ``stamp`` with bytes ``data``, and a change to log.

        ``"use"``: process it. ``"skip"``: a frame whose stamp does not advance (an error,
        :meth:`error`) or a copy of the previous picture. ``"frozen"``: from the
        ``frozen_frames``-th copy the state is FROZEN (nothing is posed) until a different
        picture comes, which restores the state before the freeze.
        """
        if self.last_stamp is not None:
            gap = stamp - self.last_stamp
            if not gap > 0:
                text = f"frame stamped {stamp:.3f} s is not newer than the last ({self.last_stamp:.3f} s)"
                return "skip", Change(self.state, text, error=True) if self.error(text) else None
            if self.period is not None and gap > 1.5 * self.period:     # against the interval before it
                self.dropped += int(round(gap / self.period)) - 1
            self.period = gap if self.period is None else min(0.95 * self.period + 0.05 * gap, gap * 1.5)
        self.last_stamp = stamp
        self.frames += 1
        if self.frozen.check(data):
            self._frozen_refused += 1
            if self.state == FROZEN:
                return "frozen", None
            self._before_freeze, self._frozen_refused = self.state, 1
            self.state = FROZEN
            return "frozen", Change(FROZEN, f"camera frozen: {self.frozen.run} identical frames in a row (same bytes, "
                                         f"fresh stamps); no pose, odometry or tf from them until the frames change",
                                 warn=True)
        if self.frozen.repeated:
            # a copy before the frozen verdict: its pose would be old content at a fresh stamp
            self.repeated_skipped += 1
            return "skip", None
        self._logged_error = None               # a usable frame: the next problem is logged again
        if self.state == FROZEN:
            self.state = self._before_freeze
            return "use", Change(self.state, f"camera frames change again after {self._frozen_refused} frozen "
                                             f"frame(s): tracking resumes")
        return "use", None

    def processed(self, stamp: float, seen: bool, publishing: bool, coasting: bool = False, reason: str | None = None,
                  latency_s: float = math.nan, compute_s: float = math.nan,
                  residual_px: float = math.nan) -> Change | None:
        """The tracker's result for an admitted frame; returns the change of state, if any.

        ``seen``: the tag was measured and accepted in this frame; ``publishing``: the tracker
        has a state to publish (a measurement or a prediction within its coast timeout);
        ``coasting``: that state is a prediction; ``reason``: why nothing was measured.
        """
        if seen:
            self.state_stamp = stamp
            self.ever_seen = True
        new = (COASTING if coasting else TRACKING) if publishing else (LOST if self.ever_seen else SEARCHING)
        self._window.append((seen, latency_s, compute_s, residual_px))
        if new == self.state:
            return None
        self.state = new
        why = f" ({reason})" if reason and new != TRACKING else ""
        if new == LOST:
            return Change(new, f"tag lost{why}: odometry stopped", warn=True)
        return Change(new, f"tag {STATE_NAMES[new]}{why}")

    def error(self, text: str) -> bool:
        """Count a refused input; True when ``text`` should be logged (a stream of the same is logged once)."""
        new = text != self._logged_error
        self._logged_error = self.last_error = text
        self.bad_frames += 1
        return new

    # -- diagnostics -----------------------------------------------------------------------
    def state_age(self, now: float) -> float:
        """Seconds from the newest frame with the tag seen to ``now`` (NaN before the first)."""
        return math.nan if self.state_stamp is None else now - self.state_stamp

    def report(self):
        """(level, message, values) for the node's diagnostics."""
        w = list(self._window)
        level, message = {
            TRACKING: (OK, "tracking"),
            COASTING: (WARN, "tag not seen: coasting on the prediction"),
            LOST: (ERROR, "tag lost: odometry stopped"),
            FROZEN: (ERROR, f"camera frozen: {self.frozen.run} identical frames in a row; odometry stopped"),
        }.get(self.state, (WARN, self.state_name))
        res = [x[3] for x in w if np.isfinite(x[3])]
        values = {"state": self.state_name,
                  "detection_rate": f"{np.mean([x[0] for x in w]):.3f}" if w else "nan",
                  "latency_ms": f"{np.median([x[1] for x in w]) * 1e3:.1f}" if w else "nan",
                  "compute_ms": f"{np.median([x[2] for x in w]) * 1e3:.2f}" if w else "nan",
                  "frames": self.frames, "dropped_frames": self.dropped, "bad_frames": self.bad_frames,
                  "frozen": self.state == FROZEN, "frozen_frames_refused": self.frozen.frozen_total,
                  "repeated_frames_skipped": self.repeated_skipped,
                  "reprojection_error_px": f"{np.median(res):.3f}" if res else "nan",
                  "last_error": self.last_error}
        return level, message, values
