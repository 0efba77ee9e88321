"""Tag-to-body offset from a straight swim: the tracker's ``offset_x/offset_y/offset_yaw``.

Model (rigid body, REP-103): the body frame's origin moves along the body's x axis (no
sideslip), its heading is ``psi = theta_tag + offset_yaw``, and the tag sits at ``c`` in
the body frame. The tag's velocity in the body frame is then ``(v - w c_y, w c_x)``
(``w`` the yaw rate), so on a straight swim with the robot's small yaw wiggles:

* ``offset_yaw``: the direction of travel in the tag frame (first per window: the chord's
  direction in the window's start tag frame minus half the window's turn; then refined so
  the tag's sideways velocity is ``w c_x`` alone);
* ``c_x`` from the lateral tag velocity against ``w``; ``c_y`` (the lateral offset) from the
  forward tag velocity against ``w``, with the forward speed a straight line in time per
  window. Both need yaw wiggles; their spread says how well the log determines them.

The tracker wants the body origin in the tag frame: ``(offset_x, offset_y) = -R(offset_yaw) c``.
Spreads are bootstrap standard deviations over the windows. Pure numpy/scipy.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from frog_common.se2 import wrap_angle

TRACKER_KEYS = ("offset_x", "offset_y", "offset_yaw")


@dataclass
class TagOffset:
    offset_x: float              # body origin in the tag frame [m]
    offset_y: float              # [m] (the lateral offset)
    offset_yaw: float            # body yaw in the tag frame [rad]
    offset_x_sd: float
    offset_y_sd: float
    offset_yaw_sd: float
    windows: int
    samples: int

    def tracker_parameters(self) -> dict:
        return {k: float(getattr(self, k)) for k in TRACKER_KEYS}


def compose(pose, offset):
    """(N, 3) poses composed with a relative pose ``offset`` (x, y, yaw)."""
    pose = np.asarray(pose, float)
    ox, oy, oa = offset
    c, s = np.cos(pose[:, 2]), np.sin(pose[:, 2])
    return np.column_stack([pose[:, 0] + c * ox - s * oy, pose[:, 1] + s * ox + c * oy, pose[:, 2] + oa])


def invert(offset):
    ox, oy, oa = offset
    c, s = math.cos(oa), math.sin(oa)
    return (-(c * ox + s * oy), -(-s * ox + c * oy), -oa)


def _windows(t, window: float, min_samples: int = 8):
    edges = np.arange(t[0], t[-1] + 1e-9, window)
    for a, b in zip(edges[:-1], edges[1:]):
        idx = np.nonzero((t >= a) & (t < b))[0]
        if len(idx) >= min_samples:
            yield idx


def estimate_tag_offset(t, tag_pose, window: float = 1.5, min_travel: float = 0.01,
                        max_turn: float = math.radians(25), bootstrap: int = 100, seed: int = 0) -> TagOffset:
    """Offset from tag poses (N, 3) at times ``t`` (N,) of a straight swim; see the module doc.

    Raises ValueError naming what is missing (too few samples, no window with travel).
    """
    from scipy.signal import savgol_filter
    t = np.asarray(t, float)
    pose = np.asarray(tag_pose, float).copy()
    if len(t) < 20 or pose.shape != (len(t), 3):
        raise ValueError(f"need >= 20 tag poses (N, 3) with their times; got {len(t)}")
    if np.any(np.diff(t) <= 0):
        raise ValueError("times must increase")
    pose[:, 2] = np.unwrap(pose[:, 2])
    dt = float(np.median(np.diff(t)))
    k = max(5, int(round(0.3 / dt)) | 1)
    smooth = savgol_filter(pose, min(k, len(t) - (1 - len(t) % 2)), 2, axis=0)
    vel = np.gradient(smooth, t, axis=0)
    yaws, rows = [], []
    for idx in _windows(t, window):
        p0, p1 = pose[idx[0]], pose[idx[-1]]
        d = p1[:2] - p0[:2]
        turn = p1[2] - p0[2]
        if np.hypot(*d) < min_travel or abs(turn) > max_turn:
            continue
        travel = math.atan2(d[1], d[0])
        yaws.append(wrap_angle(travel - p0[2] - 0.5 * turn))
        rows.append(idx)
    if not yaws:
        raise ValueError(f"no window of {window:g} s with more than {min_travel * 100:g} cm travel and less than "
                         f"{math.degrees(max_turn):.0f} deg turn: is this a straight swim?")
    yaws = np.array(yaws)
    beta0 = float(math.atan2(np.sin(yaws).mean(), np.cos(yaws).mean()))

    def fit(window_rows, beta):
        # refine the chord estimate: the tag's sideways velocity in the body frame is w c_x only
        idx = np.concatenate(window_rows)
        w = vel[idx, 2]
        for _ in range(4):
            psi = smooth[idx, 2] + beta
            fwd = np.cos(psi) * vel[idx, 0] + np.sin(psi) * vel[idx, 1]
            side = -np.sin(psi) * vel[idx, 0] + np.cos(psi) * vel[idx, 1]
            cx = float(w @ side / max(w @ w, 1e-12))
            beta += float(np.mean(side - w * cx) / np.mean(fwd))
        # body-frame tag velocity: rotate the world velocity by -(theta + beta)
        lat_a, lat_b, lon = [], [], []
        for j, idx in enumerate(window_rows):
            psi = smooth[idx, 2] + beta
            vx, vy, w = vel[idx, 0], vel[idx, 1], vel[idx, 2]
            fwd = np.cos(psi) * vx + np.sin(psi) * vy
            side = -np.sin(psi) * vx + np.cos(psi) * vy
            lat_a.append(w)
            lat_b.append(side)
            lon.append((j, t[idx] - t[idx].mean(), w, fwd))
        w_all, side_all = np.concatenate(lat_a), np.concatenate(lat_b)
        cx = float(w_all @ side_all / max(w_all @ w_all, 1e-12))
        # fwd = a_j + b_j (t - mean) - w c_y: one column per window pair, the last for c_y
        n = len(window_rows)
        blocks, y = [], []
        for j, tt, w, fwd in lon:
            m = np.zeros((len(tt), 2 * n + 1))
            m[:, 2 * j], m[:, 2 * j + 1], m[:, -1] = 1.0, tt, -w
            blocks.append(m)
            y.append(fwd)
        sol = np.linalg.lstsq(np.vstack(blocks), np.concatenate(y), rcond=None)[0]
        return beta, cx, float(sol[-1])

    def to_tracker(beta, cx, cy):
        c, s = math.cos(beta), math.sin(beta)
        return -(c * cx - s * cy), -(s * cx + c * cy)

    beta, cx, cy = fit(rows, beta0)
    ox, oy = to_tracker(beta, cx, cy)
    rng = np.random.default_rng(seed)
    boot = []
    for _ in range(bootstrap if len(rows) > 1 else 0):
        pick = rng.integers(0, len(rows), len(rows))
        b, bx, by = fit([rows[i] for i in pick], beta0)
        boot.append((*to_tracker(b, bx, by), b))
    sd = np.std(boot, axis=0, ddof=1) if len(boot) > 1 else np.full(3, np.nan)
    return TagOffset(ox, oy, beta, float(sd[0]), float(sd[1]), float(sd[2]), len(rows), int(sum(map(len, rows))))


def write_tag_offset(result: TagOffset, path, source: str = "") -> None:
    """YAML whose offset_* keys are the tracker's parameters (frog-twin --tag-offset reads it)."""
    import yaml
    data = {**result.tracker_parameters(),
            "spread": {"offset_x_sd": result.offset_x_sd, "offset_y_sd": result.offset_y_sd,
                       "offset_yaw_sd": result.offset_yaw_sd},
            "offset_yaw_deg": math.degrees(result.offset_yaw), "windows": result.windows,
            "samples": result.samples, "source": source,
            "units": "m, rad; body frame origin and yaw in the tag frame (tracker_node offset_x/y/yaw)"}
    Path(path).write_text(yaml.safe_dump(data, sort_keys=False))


def read_tag_offset(path) -> dict:
    """The tracker parameters of a tag offset file; ValueError naming the file and the problem."""
    import yaml
    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise ValueError(f"tag offset file {path}: {exc}") from exc
    if not isinstance(data, dict) or any(k not in data for k in TRACKER_KEYS):
        raise ValueError(f"tag offset file {path}: needs {', '.join(TRACKER_KEYS)} (frog-vision tag-offset)")
    out = {}
    for k in TRACKER_KEYS:
        v = data[k]
        limit = math.pi if k == "offset_yaw" else 0.5
        if not isinstance(v, (int, float)) or not math.isfinite(v) or abs(v) > limit:
            raise ValueError(f"tag offset file {path}: {k} = {v!r} is not a number within +-{limit:g}")
        out[k] = float(v)
    return out
