"""Metrics of a closed-loop run, computed from recorded samples alone (SI units).

Used by the in-process evaluator, the main job and the twin alike, so a figure means the
same wherever it is printed. Nothing here knows about the planner's own bookkeeping: the
distance is pure geometry against the reference polyline, so a planner bug cannot hide in
its own progress estimate.
"""

from __future__ import annotations

from collections import Counter

import numpy as np
from frog_common.se2 import wrap_angle


def distance_to_polyline(points, path) -> np.ndarray:
    """Euclidean distance [m] of each point (N, 2) to the polyline ``path`` (M, 2), M >= 2."""
    p = np.asarray(points, dtype=float).reshape(-1, 2)[:, None, :]
    ref = np.asarray(path, dtype=float)
    a, d = ref[:-1], np.diff(ref, axis=0)
    t = np.clip(((p - a) * d).sum(-1) / np.maximum((d * d).sum(-1), 1e-300), 0.0, 1.0)
    return np.min(np.linalg.norm(a + t[..., None] * d - p, axis=-1), axis=1)


def signed_lateral_offset(points, path) -> np.ndarray:
    """Signed distance [m] of each point (N, 2) to the polyline ``path`` (M, 2): + left of the path.

    "Left" is seen along the path's direction (from its first point to its last): the sign
    is that of the cross product of the closest segment's direction and the vector from
    the segment's start to the point. Its magnitude is :func:`distance_to_polyline`.
    """
    p = np.asarray(points, dtype=float).reshape(-1, 2)[:, None, :]
    ref = np.asarray(path, dtype=float)
    a, d = ref[:-1], np.diff(ref, axis=0)
    t = np.clip(((p - a) * d).sum(-1) / np.maximum((d * d).sum(-1), 1e-300), 0.0, 1.0)
    dist = np.linalg.norm(a + t[..., None] * d - p, axis=-1)
    k = np.argmin(dist, axis=1)
    rel = p[:, 0, :] - a[k]
    cross = d[k, 0] * rel[:, 1] - d[k, 1] * rel[:, 0]
    return np.where(cross < 0.0, -1.0, 1.0) * dist[np.arange(len(k)), k]


def path_progress(positions, path, window: float = 0.3) -> np.ndarray:
    """Arc length [m] along ``path`` (M, 2) of each sample's closest point, tracked forward.

    Sample by sample, the closest point is searched only on the stretch of ``window`` metres
    ahead of the previous sample's (from 0 for the first), so the progress never decreases and
    a path that ends near its start (an ellipse) is not taken for its end at the start, nor for
    its start at the end. Pure geometry, the same for a real log and a simulated run.
    """
    pts = np.asarray(positions, dtype=float).reshape(-1, 2)
    ref = np.asarray(path, dtype=float)
    a, d = ref[:-1], np.diff(ref, axis=0)
    seg_len = np.linalg.norm(d, axis=1)
    cum = np.r_[0.0, np.cumsum(seg_len)]
    out = np.empty(len(pts))
    s_prev = 0.0
    for i, p in enumerate(pts):
        lo = min(max(int(np.searchsorted(cum, s_prev, side="right")) - 1, 0), len(d) - 1)
        hi = min(int(np.searchsorted(cum, s_prev + window, side="left")), len(d))
        hi = max(hi, lo + 1)
        k = np.arange(lo, hi)
        t = np.einsum("ij,ij->i", p - a[k], d[k]) / np.maximum(seg_len[k] ** 2, 1e-300)
        s = np.clip(cum[k] + np.clip(t, 0.0, 1.0) * seg_len[k], s_prev, s_prev + window)
        # the closest point of each segment within the window (its ends clipped to the window)
        tt = (s - cum[k]) / np.maximum(seg_len[k], 1e-300)
        dist = np.linalg.norm(a[k] + tt[:, None] * d[k] - p, axis=1)
        j = int(np.argmin(dist))
        s_prev = max(s_prev, float(s[j]))
        out[i] = s_prev
    return out


def finish_index(positions, path, goal_tolerance: float | None = None,
                 lateral_tolerance: float | None = None) -> int:
    """Index of the first sample at which the robot has finished the path, or the number of samples.

    Finished: crossing the finish line, the normal through the path's end to its last segment,
    once the tracked progress (:func:`path_progress`) has reached the end, within
    ``lateral_tolerance`` of the end along that line at the crossing (None: anywhere; a robot
    that crosses wide and drifts into the band afterwards has not finished there, as the
    planner's goal test); or, with ``goal_tolerance``, within that distance of the end once the
    tracked progress has passed half the path.
    """
    pts = np.asarray(positions, dtype=float).reshape(-1, 2)
    ref = np.asarray(path, dtype=float)
    s = path_progress(pts, ref)
    length = float(np.sum(np.linalg.norm(np.diff(ref, axis=0), axis=1)))
    tangent = ref[-1] - ref[-2]
    tangent = tangent / np.linalg.norm(tangent)
    rel = pts - ref[-1]
    along = rel @ tangent
    lateral = rel[:, 1] * tangent[0] - rel[:, 0] * tangent[1]
    done = np.zeros(len(pts), dtype=bool)
    crossing = np.r_[False, (along[:-1] <= 0.0) & (along[1:] > 0.0)] & (s >= length - 1e-9)
    if lateral_tolerance is None:
        done |= crossing
    else:
        for i in np.nonzero(crossing)[0]:       # the lateral offset where the step crossed the line
            w = -along[i - 1] / (along[i] - along[i - 1])
            done[i] = abs(lateral[i - 1] + w * (lateral[i] - lateral[i - 1])) <= lateral_tolerance
    if goal_tolerance is not None:
        done |= (s >= 0.5 * length) & (np.linalg.norm(rel, axis=1) <= goal_tolerance)
    hits = np.nonzero(done)[0]
    return int(hits[0]) if len(hits) else len(pts)


def finish_time(time, positions, path, goal_tolerance: float = 0.03, lateral_tolerance: float | None = None):
    """When the robot finished the path [s] (same clock as ``time``), or None: the first sample
    within ``goal_tolerance`` of the path's end after half the path, or past the finish line
    (within ``lateral_tolerance`` of the end along it; None: anywhere), see
    :func:`finish_index`. Pure geometry, so a real log and a simulated run are timed alike."""
    t = np.asarray(time, dtype=float)
    first = finish_index(positions, path, goal_tolerance, lateral_tolerance)
    return float(t[first]) if first < len(t) else None


def samples_before_finish(positions, path_points) -> int:
    """Number of samples before the robot crosses the finish line (the normal to the path
    at its end) on its final approach, :func:`finish_index` at any lateral distance: past it,
    the distance to the polyline measures overshoot beyond the goal, not tracking."""
    return finish_index(positions, path_points)


def arc_length_progress(points, path) -> np.ndarray:
    """Arc length [m] along ``path`` of each point's closest point (no monotonicity imposed)."""
    ref = np.asarray(path, dtype=float)
    seg = np.diff(ref, axis=0)
    seg_len = np.linalg.norm(seg, axis=1)
    cum = np.r_[0.0, np.cumsum(seg_len)]
    p = np.asarray(points, dtype=float).reshape(-1, 2)[:, None, :]
    t = np.clip(((p - ref[:-1]) * seg).sum(-1) / np.maximum(seg_len ** 2, 1e-300), 0.0, 1.0)
    dist = np.linalg.norm(ref[:-1] + t[..., None] * seg - p, axis=-1)
    k = np.argmin(dist, axis=1)
    return cum[k] + t[np.arange(len(k)), k] * seg_len[k]


def tracking_metrics(time, positions, path, goal_time=None, primitives=()) -> dict:
    """Mean/max distance to the path, completion time, speed along the path, primitives used.

    Parameters
    ----------
    time : array_like, shape (N,)
        Sample times [s], increasing; the run starts at ``time[0]``.
    positions : array_like, shape (N, 2)
        True positions [m] in the path's frame.
    path : array_like, shape (M, 2)
        Reference polyline [m].
    goal_time : float, optional
        When the goal was reached [s] (same clock as ``time``); None if it was not.
    primitives : iterable of str
        Names of the primitives sent, one per decision ('I' counts as no action).

    Returns
    -------
    dict
        ``mean_distance_m``, ``max_distance_m`` (samples up to the goal or the finish line),
        ``mean_signed_lateral_m`` (the same samples' signed offset, + left of the path's
        direction, see :func:`signed_lateral_offset`),
        ``completion_time_s`` (None without a goal), ``final_progress`` (0-1, by arc length of
        the last sample's closest point), ``mean_speed_along_path_m_per_s`` (arc length
        covered / elapsed time), ``primitives_used`` (counts, 'I' excluded).
    """
    t = np.asarray(time, dtype=float)
    xy = np.asarray(positions, dtype=float).reshape(-1, 2)
    ref = np.asarray(path, dtype=float)
    if len(t) != len(xy) or len(t) < 2:
        raise ValueError(f"need >= 2 samples with one time each, got {len(t)} times and {len(xy)} positions")
    keep = np.ones(len(t), dtype=bool)
    if goal_time is not None:
        keep &= t <= goal_time + 1e-9
    n = samples_before_finish(xy[keep], ref)
    t, xy = t[keep][:max(n, 1)], xy[keep][:max(n, 1)]
    dist = distance_to_polyline(xy, ref)
    lateral = signed_lateral_offset(xy, ref)
    length = float(np.sum(np.linalg.norm(np.diff(ref, axis=0), axis=1)))
    s = arc_length_progress(xy, ref)
    end = (goal_time if goal_time is not None else t[-1]) - float(np.asarray(time, dtype=float)[0])
    covered = length if goal_time is not None else float(s[-1] - s[0])
    return {
        "mean_distance_m": float(dist.mean()), "max_distance_m": float(dist.max()),
        "mean_signed_lateral_m": float(lateral.mean()),
        "completion_time_s": float(end) if goal_time is not None else None,
        "final_progress": 1.0 if goal_time is not None else float(s[-1] / length),
        "mean_speed_along_path_m_per_s": covered / end if end > 0 else 0.0,
        "primitives_used": dict(sorted(Counter(p for p in primitives if p != "I").items())),
        "path_length_m": length,
    }


def pose_errors(est_time, est_pose, true_time, true_pose) -> dict:
    """Errors of estimated poses (x, y, heading) against the truth interpolated at their times.

    Headings are unwrapped before interpolation and errors wrapped to [-pi, pi). Estimates
    outside the truth's time span are ignored.
    """
    te, pe = np.asarray(est_time, dtype=float), np.asarray(est_pose, dtype=float).reshape(-1, 3)
    tt, pt = np.asarray(true_time, dtype=float), np.asarray(true_pose, dtype=float).reshape(-1, 3)
    inside = (te >= tt[0]) & (te <= tt[-1])
    te, pe = te[inside], pe[inside]
    if len(te) == 0:
        raise ValueError("no estimate lies within the ground truth's time span")
    x = np.interp(te, tt, pt[:, 0])
    y = np.interp(te, tt, pt[:, 1])
    h = np.interp(te, tt, np.unwrap(pt[:, 2]))
    pos = np.hypot(pe[:, 0] - x, pe[:, 1] - y)
    head = np.abs(wrap_angle(pe[:, 2] - h))
    return {"n": int(len(te)), "position_mean_m": float(pos.mean()), "position_max_m": float(pos.max()),
            "heading_mean_rad": float(head.mean()), "heading_max_rad": float(head.max()),
            "position_error_m": pos, "heading_error_rad": head, "time_s": te}


def latency_stats(sent_times, fired_times) -> dict:
    """Median / p99 / max of (fired - sent) [s], pairing each firing with the latest send before it."""
    sent = np.sort(np.asarray(sent_times, dtype=float))
    fired = np.asarray(fired_times, dtype=float)
    if len(sent) == 0 or len(fired) == 0:
        return {"n": 0, "median_s": None, "p99_s": None, "max_s": None}
    k = np.searchsorted(sent, fired, side="right") - 1
    ok = k >= 0
    lat = fired[ok] - sent[k[ok]]
    if len(lat) == 0:
        return {"n": 0, "median_s": None, "p99_s": None, "max_s": None}
    return {"n": int(len(lat)), "median_s": float(np.median(lat)), "p99_s": float(np.percentile(lat, 99)),
            "max_s": float(lat.max())}


def best_window_rate(times, window: float) -> float | None:
    """The highest rate [1/s] of events ``times`` [s] in any complete window of ``window`` s
    starting at an event: (events in [t_i, t_i + window]) - 1, over ``window``; None until the
    events span a whole window. A start-up stall (the pre-flight's first seconds, when every
    node is loading) lowers one window, not the best."""
    t = np.sort(np.asarray(times, dtype=float))
    if t.size < 2 or t[-1] - t[0] < window:
        return None
    starts = t[t <= t[-1] - window]
    ends = np.searchsorted(t, starts + window, side="right")
    counts = ends - np.searchsorted(t, starts, side="left")
    return float((counts.max() - 1) / window)
