"""How old was the state behind each limb pulse? An audit of a recording, trusting no node.

Every pulse the bridge writes is recorded on ``frog/bridge/sent``; every pose the tracker
publishes on ``frog/odom``, and for each frame ``frog/tracker/state`` says whether that pose was
measured or predicted. The audit takes, for each pulse, the newest *measured* pose that existed
before it (by the middleware's publish times, which no node computes; the recorder's receive
times are reported beside them) and its age when the pulse was written: the pulse's stamp minus the
pose's capture stamp, both on the node clock the bound is defined on (simulated time in the twin,
so a paused or slowed world does not count as age). It also reads the age the
bridge itself recorded (``LimbActivation.state_age``): that needs no trust in the planner. A
pulse is on a stale state if the bridge's record exceeds the bound, or, where the recording is
known to be complete (the recorder up, and not in the seconds after a restarted tracker before
the recorder has matched it: :func:`complete_intervals`), if the recorded poses say so. Without
tracker states in the recording (odometry from the simulator), every odometry message is a
measurement.
"""
from __future__ import annotations

import bisect
from dataclasses import dataclass, field

import numpy as np

from frog_common.state_age import older_than


@dataclass
class PulseAges:
    """The ages of the state behind each pulse [s], and the bound they were held to."""

    bound_s: float
    published: np.ndarray = field(default_factory=lambda: np.zeros(0))   # from publish times
    received: np.ndarray = field(default_factory=lambda: np.zeros(0))    # from the recorder's receive times
    claimed: np.ndarray = field(default_factory=lambda: np.zeros(0))     # the bridge's own state_age
    times: np.ndarray = field(default_factory=lambda: np.zeros(0))       # each pulse's publish time (wall)
    stamps: np.ndarray = field(default_factory=lambda: np.zeros(0))      # each pulse's header stamp (node clock)
    complete: list | None = None       # [(t0, t1)] of stamps where the recording is complete (None: all of it)

    @property
    def n(self) -> int:
        return len(self.times)

    def judged(self) -> np.ndarray:
        """Which pulses the recorded poses can judge: those inside an interval of a complete recording."""
        if self.complete is None:
            return np.ones(self.n, dtype=bool)
        return np.array([any(a <= t <= b for a, b in self.complete) for t in self.stamps], dtype=bool)

    def stale(self) -> list[dict]:
        """Pulses on a state older than the bound: by the bridge's record, or by the recorded poses (their
        publish times) where the recording is complete: {t, stamp, published, received, claimed}.

        The receive times are reported, not judged: the recorder takes each topic's queue in turn, so a
        pulse can be received before odometry published earlier (seen: 5.3 s apart while the recorder
        caught up after a restarted camera), which is the recorder's order, not the robot's."""
        recorded = self.judged() & older_than(self.published, self.bound_s)
        bad = recorded | older_than(self.claimed, self.bound_s)
        return [{"t": float(self.times[i]), "stamp": float(self.stamps[i]), "published": float(self.published[i]),
                 "received": float(self.received[i]), "claimed": float(self.claimed[i])} for i in np.flatnonzero(bad)]

    def summary(self) -> dict:
        def stat(a):
            a = a[np.isfinite(a)]
            return {"median": float(np.median(a)), "p99": float(np.quantile(a, 0.99)), "max": float(a.max())} \
                if len(a) else None
        judged = self.judged()
        return {"pulses": self.n, "bound_s": self.bound_s, "stale": len(self.stale()), "judged": int(judged.sum()),
                "published": stat(self.published[judged]), "received": stat(self.received[judged]),
                "claimed": stat(self.claimed)}


def complete_intervals(up, holes, margin: float = 1.0) -> list:
    """[(t0, t1)] where a recording is complete: each interval of ``up`` (the recorder up; its first
    ``margin`` s left out, while its subscriptions match) without the ``holes`` (after a restarted
    publisher, until the recorder has matched it)."""
    out = [(a + margin, b) for a, b in up if b > a + margin]
    for h0, h1 in sorted(holes):
        cut = []
        for a, b in out:
            if h1 <= a or h0 >= b:
                cut.append((a, b))
                continue
            if h0 > a:
                cut.append((a, h0))
            if h1 < b:
                cut.append((h1, b))
        out = cut
    return out


def measured_poses(odom, states=None):
    """The (publish time, receive time, stamp) of the odometry that was measured, by publish time.

    ``odom``: (header stamp, publish time, receive time) per frog/odom message; ``states``:
    {header stamp: state stamp} of frog/tracker/state (None: every pose is measured). A pose
    is measured when the tracker's state for its frame has the frame's own stamp; a pose
    without a recorded state counts as predicted (not trusted as fresh).
    """
    rows = [(p, r, stamp) for stamp, p, r in odom
            if states is None or abs(states.get(round(stamp, 6), -1.0) - stamp) < 1e-6]
    return sorted(rows)


def pulse_ages(pulses, measured, bound_s: float) -> PulseAges:
    """Ages of the state behind each pulse.

    ``pulses``: (publish time, receive time, claimed state age, header stamp) per frog/bridge/sent message;
    ``measured``: from :func:`measured_poses`. A pulse with no measured pose before it gets an
    infinite age (it rests on nothing the audit can see).
    """
    pub = [p for p, _, _ in measured]
    by_receipt = sorted((r, st) for _, r, st in measured)
    rec = [r for r, _ in by_receipt]
    # the newest capture among the measurements that existed by each one (a later frame captured
    # earlier cannot make the state younger)
    newest_pub = np.maximum.accumulate([st for _, _, st in measured]) if measured else np.zeros(0)
    newest_rec = np.maximum.accumulate([st for _, st in by_receipt]) if measured else np.zeros(0)
    out = PulseAges(bound_s)
    rows = sorted(pulses)
    if not rows:
        return out
    times, published, received, claimed, stamps = [], [], [], [], []
    for p, r, claim, stamp in rows:
        i = bisect.bisect_right(pub, p) - 1
        j = bisect.bisect_right(rec, r) - 1
        times.append(p)
        # the newest measurement that existed before the pulse (by its time), aged on the node clock
        published.append(stamp - newest_pub[i] if i >= 0 else np.inf)
        received.append(stamp - newest_rec[j] if j >= 0 else np.inf)
        claimed.append(claim)
        stamps.append(stamp)
    out.times, out.published, out.received, out.claimed, out.stamps = (
        np.array(v, dtype=float) for v in (times, published, received, claimed, stamps))
    return out
