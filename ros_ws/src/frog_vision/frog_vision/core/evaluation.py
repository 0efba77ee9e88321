"""Accuracy of the tracker on rendered sequences against the renderer's exact ground truth.

Used by the unit tests (thresholds), ``bench/vision_accuracy.py`` (the table) and
``frog-vision render``. The baseline is the authors' method: raw frame-to-frame
differences of the measured poses.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from frog_vision.core.renderer import Occluder, TankRenderer
from frog_vision.core.robot_shape import frog_outline
from frog_vision.core.frame_difference import raw_differences
from frog_vision.core.synthetic import Trajectory
from frog_vision.core.tracker import Tracker
from frog_common.se2 import wrap_angle


@dataclasses.dataclass
class SequenceResult:
    """Per-frame results of one rendered sequence (NaN where nothing was estimated)."""

    truth: Trajectory
    measured: np.ndarray        # (N, 3) tag-derived body pose per frame
    filtered: np.ndarray        # (N, 3)
    velocity: np.ndarray        # (N, 3) filtered body twist
    detected: np.ndarray        # (N,) bool: accepted measurement
    occluded: np.ndarray        # (N,) bool
    dropped: np.ndarray         # (N,) bool: frame lost (never given to the tracker)
    compute_s: np.ndarray       # (N,)

    def metrics(self, skip_s: float = 0.5) -> dict:
        """Figures of the table (errors in mm, deg, mm/s, deg/s)."""
        t = self.truth.t
        ok = self.detected & (t >= t[0] + skip_s)
        pos_err = np.linalg.norm(self.measured[ok, :2] - self.truth.pose[ok, :2], axis=1) * 1e3
        head_err = np.degrees(np.abs(wrap_angle(self.measured[ok, 2] - self.truth.pose[ok, 2])))
        est = np.isfinite(self.velocity[:, 0]) & (t >= t[0] + skip_s) & ~self.dropped
        verr = np.linalg.norm(self.velocity[est, :2] - self.truth.twist[est, :2], axis=1) * 1e3
        werr = np.degrees(np.abs(self.velocity[est, 2] - self.truth.twist[est, 2]))
        # raw differences over consecutive accepted measurements
        idx = np.flatnonzero(self.detected)
        raw = raw_differences(t[idx], self.measured[idx])
        keep = (t[idx] >= t[0] + skip_s) & np.isfinite(raw[:, 0])
        keep[1:] &= np.diff(idx) == 1          # only true frame-to-frame pairs
        rerr = np.linalg.norm(raw[keep, :2] - self.truth.twist[idx[keep], :2], axis=1) * 1e3
        rwerr = np.degrees(np.abs(raw[keep, 2] - self.truth.twist[idx[keep], 2]))
        visible = ~self.occluded & ~self.dropped
        rms = lambda e: float(np.sqrt(np.mean(e ** 2))) if len(e) else float("nan")  # noqa: E731
        return {
            "position_mean_mm": float(pos_err.mean()) if len(pos_err) else float("nan"),
            "position_max_mm": float(pos_err.max()) if len(pos_err) else float("nan"),
            "heading_mean_deg": float(head_err.mean()) if len(head_err) else float("nan"),
            "heading_max_deg": float(head_err.max()) if len(head_err) else float("nan"),
            "velocity_rms_mm_s": rms(verr),
            "raw_velocity_rms_mm_s": rms(rerr),
            "velocity_ratio": rms(rerr) / rms(verr) if len(verr) else float("nan"),
            "yaw_rate_rms_deg_s": rms(werr),
            "raw_yaw_rate_rms_deg_s": rms(rwerr),
            "yaw_rate_ratio": rms(rwerr) / rms(werr) if len(werr) else float("nan"),
            "detection_rate": float(self.detected[visible].mean()) if visible.any() else float("nan"),
            "compute_median_ms": float(np.median(self.compute_s[~self.dropped]) * 1e3),
        }

    def frames_to_recover(self) -> int | None:
        """Frames after the last occluded frame until the first accepted measurement."""
        occ = np.flatnonzero(self.occluded)
        if not len(occ):
            return None
        after = np.flatnonzero(self.detected[occ[-1] + 1:])
        return int(after[0]) + 1 if len(after) else None


def run_sequence(renderer: TankRenderer, tracker: Tracker, truth: Trajectory, occlusion=(),
                 tag_offset=None, progress=None, shapes=None, kicks=(),
                 occluder_radius: float = 0.06) -> SequenceResult:
    """Render every frame of ``truth`` and track it.

    Parameters
    ----------
    occlusion : sequence of (t0, t1)
        The tag is hidden by an occluder during these intervals [s].
    tag_offset : (x, y, yaw), optional
        The tag's pose in the body frame (default: ring centre).
    progress : callable, optional
        Wraps the frame iterator (e.g. ``tqdm``).
    shapes : sequence of RobotShape, optional
        One body-frame shape per frame (e.g. the simulator's); the tag then sits on each
        frame's ring centre. Default: the outline with ``truth.limb_curl``.
    kicks : sequence of float
        Limb firing times [s], each given to the tracker before the first frame captured
        at or after it (as the node gets the bridge's message); empty: no inputs.
    occluder_radius : float
        Radius of the occluder [m].
    """
    n = len(truth.t)
    measured = np.full((n, 3), np.nan)
    filtered = np.full((n, 3), np.nan)
    vel = np.full((n, 3), np.nan)
    detected = np.zeros(n, bool)
    occluded = np.zeros(n, bool)
    dropped = np.zeros(n, bool)
    compute = np.zeros(n)
    pending = sorted(float(k) for k in kicks)
    frames = range(n) if progress is None else progress(range(n))
    for i in frames:
        t = truth.t[i]
        while pending and pending[0] <= t + 1e-9:
            tracker.kick(pending.pop(0))
        if shapes is not None:
            shape = shapes[i]
            tag_offset = (float(shape.ring_centre[0]), float(shape.ring_centre[1]), 0.0)
        else:
            shape = frog_outline(limb_curl=float(truth.limb_curl[i]))
        occ = []
        if any(a <= t < b for a, b in occlusion):
            p = truth.pose[i]
            occ = [Occluder(p[0], p[1], occluder_radius)]
            occluded[i] = True
        if renderer.should_drop():
            dropped[i] = True
            continue
        img = renderer.render(truth.pose[i], truth.twist[i], shape, tag_offset, occ)
        r = tracker.process(img, float(t))
        compute[i] = r.compute_s
        if r.measurement is not None:
            measured[i] = r.measurement.pose
            detected[i] = True
        if r.state is not None:
            filtered[i] = r.state.pose
            vel[i] = r.state.body_velocity
    return SequenceResult(truth, measured, filtered, vel, detected, occluded, dropped, compute)
