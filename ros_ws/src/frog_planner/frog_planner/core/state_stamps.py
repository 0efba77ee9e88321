"""Odometry paired with the state it rests on: the capture stamp of its measurement.

A pose the tracker predicted while the tag was not seen is stamped with the frame it was
predicted for, but the information in it is as old as the last frame in which the tag was
seen. The tracker says which for every frame (``frog/tracker/state``: same header stamp as
the odometry, and ``state_stamp``). :class:`StateStamps` pairs the two streams by header
stamp (they arrive on two topics, in either order) and gives the newest odometry whose state
stamp is known. Without a tracker (odometry from the simulator, or any source whose stamps are
its measurements) every odometry is its own state.

Stamps are seconds on the node's clock; they are matched exactly (the same ``sec``,
``nanosec`` give the same float).
"""
from __future__ import annotations

import collections
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class StateSample:
    """One odometry message with the stamp of the measurement behind it [s]."""

    pose: np.ndarray          # x m, y m, heading rad (world frame)
    twist: np.ndarray         # forward m/s, lateral m/s, yaw rate rad/s (body frame)
    stamp: float              # the odometry's header stamp: when the pose holds
    state_stamp: float        # when the information in it was measured (<= stamp)


class StateStamps:
    """The newest odometry with a known state stamp (see the module docstring).

    Parameters
    ----------
    paired : bool
        True: state stamps come from :meth:`tracker_state` messages; False: each odometry's
        stamp is its state stamp.
    keep : int
        Unpaired messages kept per stream (about a second of frames at 30 Hz by default).

    Examples
    --------
    >>> s = StateStamps(paired=True)
    >>> s.odometry((0, 0, 0), (0, 0, 0), 10.0)
    []
    >>> [x.state_stamp for x in s.tracker_state(10.0, 9.5)]      # a prediction since 9.5 s
    [9.5]
    >>> s.newest.stamp, s.newest.state_stamp
    (10.0, 9.5)
    """

    def __init__(self, paired: bool, keep: int = 32):
        self.paired = paired
        self._odometry = collections.OrderedDict()   # stamp -> (pose, twist), unpaired
        self._states = collections.OrderedDict()     # stamp -> state stamp, unpaired
        self._keep = keep
        self.newest: StateSample | None = None
        self.unpaired_odometry = 0                   # odometry dropped without its state: counted

    def odometry(self, pose, twist, stamp: float) -> list[StateSample]:
        """An odometry message; returns the samples it completes (none, or itself)."""
        pose, twist = np.asarray(pose, dtype=float), np.asarray(twist, dtype=float)
        if not self.paired:
            return self._complete(StateSample(pose, twist, stamp, stamp))
        if stamp in self._states:
            return self._complete(StateSample(pose, twist, stamp, self._states.pop(stamp)))
        self._odometry[stamp] = (pose, twist)
        while len(self._odometry) > self._keep:
            self._odometry.popitem(last=False)
            self.unpaired_odometry += 1
        return []

    def tracker_state(self, stamp: float, state_stamp: float | None) -> list[StateSample]:
        """The tracker's state for the frame stamped ``stamp`` (``state_stamp`` None: the tag never seen)."""
        if not self.paired or state_stamp is None:
            return []
        if stamp in self._odometry:
            pose, twist = self._odometry.pop(stamp)
            return self._complete(StateSample(pose, twist, stamp, min(state_stamp, stamp)))
        self._states[stamp] = min(state_stamp, stamp)
        while len(self._states) > self._keep:
            self._states.popitem(last=False)      # a frame with no pose (lost, frozen): nothing to pair
        return []

    def _complete(self, sample: StateSample) -> list[StateSample]:
        # a late pair of an older frame does not replace a newer one; a clock that went back
        # (a restarted simulator) starts over
        if self.newest is None or sample.stamp >= self.newest.stamp or sample.stamp < self.newest.stamp - 1.0:
            self.newest = sample
        return [sample]

    def clear(self) -> None:
        """Forget everything (a new run)."""
        self._odometry.clear()
        self._states.clear()
        self.newest = None
