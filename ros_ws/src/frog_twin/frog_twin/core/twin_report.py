"""Figures, plots and the tracker-style video of a twin run (from its recording only).

Metrics come from :mod:`frog_twin.core.metrics`; the distance to the path is measured on
the simulator's ground truth (the robot's true centre of mass), the vision error is the
tracker's pose against that truth, and the latency is from the planner's decision stamp to
the emulated robot's firing stamp (simulated time: it includes the serial link, the relay's
BLE delay and the front/rear pulse schedule).
"""

from __future__ import annotations

import math

import numpy as np

from .metrics import latency_stats, pose_errors, tracking_metrics
from .twin_recording import TwinRecording

#: The real robot's closed-loop figures from the paper's logs (mean distance to the path, cm;
#: speed along the path, cm/s), printed beside the twin's.
HARDWARE = {"line": (0.5, 1.4), "sine": (1.7, 3.3), "sinusoid": (1.7, 3.3), "ellipse": (1.8, 4.1),
            "speed_cm_per_s": (1.4, 2.8)}

STATE_GOAL_REACHED = 2   # PlannerStatus.STATE_GOAL_REACHED (the core does not import messages)


def run_metrics(rec: TwinRecording, path_name: str, end_time: float | None = None) -> dict:
    """All figures of one run (SI units), from the recording.

    ``end_time`` [s, the recording's clock] ends the run: what the recorder caught after it
    (the world runs on while the nodes are stopped, longer on a loaded machine) is not scored.
    """
    if rec.path is None or len(rec.truth) < 2:
        raise ValueError("the recording has no reference path or too little ground truth")
    end = np.inf if end_time is None else float(end_time)
    goal_rows = rec.status[rec.status[:, 8] == STATE_GOAL_REACHED] if len(rec.status) else rec.status
    goal_time = float(goal_rows[0, 0]) if len(goal_rows) else None
    following = rec.status[rec.status[:, 8] == 1] if len(rec.status) else rec.status
    start = float(following[0, 0]) if len(following) else float(rec.truth[0, 0])
    in_run = rec.truth[rec.truth[:, 0] <= end + 1e-9]
    truth = in_run[in_run[:, 0] >= start - 1e-9]
    if len(truth) < 2:      # a run stopped at once (real mode: one pose after the start): its last two poses
        truth = in_run[-2:] if len(in_run) >= 2 else rec.truth[:2]
    last = end if goal_time is None else min(goal_time, end)
    prims = [n for t, n in rec.primitives if start - 1e-9 <= t < last - 1e-9]
    m = tracking_metrics(truth[:, 0], truth[:, 1:3], rec.path, goal_time=goal_time, primitives=prims)
    m["path"] = path_name
    m["start_time_s"] = start
    m["decisions"] = len(prims)
    if len(rec.tracked) >= 2:
        e = pose_errors(rec.tracked[:, 0], rec.tracked[:, 1:4], rec.truth[:, 0], rec.truth[:, 1:4])
        m["vision"] = {"n": e["n"], "position_mean_m": e["position_mean_m"], "position_max_m": e["position_max_m"],
                       "heading_mean_rad": e["heading_mean_rad"], "heading_max_rad": e["heading_max_rad"],
                       "rate_hz": float(len(rec.tracked) / max(rec.tracked[-1, 0] - rec.tracked[0, 0], 1e-9))}
    else:
        m["vision"] = None
    decided = [t for t, n in rec.primitives if n != "I"]
    m["latency_decision_to_firing"] = latency_stats(decided, [t for t, limbs in rec.fired if limbs])
    m["latency_decision_to_serial"] = latency_stats(decided, [t for t, limbs in rec.sent if limbs])
    m["limb_firings"] = sum(1 for t, limbs in rec.fired if limbs and t <= end + 1e-9)
    m["end_time_s"] = None if end_time is None else end
    m["tf_frames"] = {f"{a} -> {b}": n for (a, b), n in sorted(rec.tf_frames.items())}
    m["hardware_mean_distance_cm"] = HARDWARE.get(path_name)
    m["hardware_speed_cm_per_s"] = HARDWARE["speed_cm_per_s"]
    m["units"] = {"distance": "m", "time": "s (simulated)", "speed": "m/s", "angle": "rad"}
    return m


def feasibility(library_file, settings, path_points, goal_tolerance: float) -> dict:
    """Where the path is tighter than the frog can turn, and the best mean distance one could hope for.

    The frog's steady turning circles come from the planner's own transition model (the
    library the planner used, with its settings); see :mod:`frog_planner.core.feasibility`.
    """
    from frog_planner.core.feasibility import steady_turns, tight_stretches, turning_limited_floor, turning_limits
    from frog_planner.core.paths import Path
    from frog_planner.core.transition_model import TransitionModel
    model = TransitionModel.load(library_file, **settings.model_kwargs())
    limits = turning_limits(steady_turns(model, settings.period))
    path = Path(np.asarray(path_points, dtype=float), n_points=len(path_points), goal_tolerance=goal_tolerance)
    tight = tight_stretches(path, limits)
    floor = turning_limited_floor(path, limits)
    return {"turn_radius_left_m": limits.left_m, "turn_radius_right_m": limits.right_m,
            "steady_turns": {t.primitive: {"radius_m": t.radius_m, "yaw_per_period_rad": t.yaw_per_period_rad,
                                           "speed_m_per_s": t.speed_m_per_s} for t in limits.turns},
            "tight_stretches": tight,
            "tight_share": sum(t["end_m"] - t["start_m"] for t in tight) / path.length,
            "path_min_radius_m": float(1.0 / np.max(np.abs(path.curvatures))) if np.any(path.curvatures)
            else float("inf"),
            "floor_mean_distance_m": floor.mean_distance_m, "straight_cut_m": floor.straight_cut_m,
            "floor_curve": floor.points.tolist()}


def plot_run(rec: TwinRecording, metrics: dict, png, weights=(500.0, 50.0, 300.0)) -> None:
    """Fig. 5d-f (true, tracked and reference paths), Fig. 5g (distance), Fig. S3 (costs), vision error."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from .metrics import distance_to_polyline
    t0 = metrics["start_time_s"]
    fig, axes = plt.subplots(2, 2, figsize=(14, 10))
    ax = axes[0, 0]
    every = max(1, len(rec.shapes) // 14)
    for _, pts in rec.shapes[::every]:
        seg = pts.reshape(-1, 2, 2) * 100
        ax.plot(seg[:, :, 0].T, seg[:, :, 1].T, color="tab:green", alpha=0.2, lw=0.7)
    ax.plot(rec.path[:, 0] * 100, rec.path[:, 1] * 100, "k--", lw=1.3, label="reference path")
    feas = metrics.get("feasibility")
    if feas:
        arc = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(rec.path, axis=0), axis=1))]
        r_turn = min(feas["turn_radius_left_m"], feas["turn_radius_right_m"]) * 100
        for i, t in enumerate(feas["tight_stretches"]):
            on = (arc >= t["start_m"] - 1e-9) & (arc <= t["end_m"] + 1e-9)
            ax.plot(rec.path[on, 0] * 100, rec.path[on, 1] * 100, color="tab:red", lw=5, alpha=0.35,
                    label=None if i else f"tighter than the frog's turn (r < {r_turn:.1f} cm)")
        if feas["tight_stretches"] and len(feas["floor_curve"]):
            fc = np.asarray(feas["floor_curve"])
            ax.plot(fc[:, 0] * 100, fc[:, 1] * 100, color="0.45", lw=1.0,
                    label=f"best turning-limited cut ({feas['floor_mean_distance_m'] * 100:.2f} cm)")
    ax.plot(rec.truth[:, 1] * 100, rec.truth[:, 2] * 100, color="tab:blue", lw=1.6, label="true path (simulator)")
    if len(rec.tracked):
        ax.plot(rec.tracked[:, 1] * 100, rec.tracked[:, 2] * 100, ":", color="tab:orange", lw=1.4,
                label="tracked (camera + tracker)")
    ax.plot(*(rec.path[-1] * 100), "r*", ms=13, label="goal")
    ax.set_aspect("equal")
    ax.set(xlabel="x [cm] (tank)", ylabel="y [cm]", title=f"{metrics['path']}: digital twin, closed loop")
    ax.legend(fontsize=8)
    ax = axes[0, 1]
    tt = rec.truth[:, 0]
    end = t0 + metrics["completion_time_s"] if metrics["completion_time_s"] is not None else tt[-1]
    keep = (tt >= t0) & (tt <= end + 1e-9)     # up to the goal: coasting past it is not tracking
    d = distance_to_polyline(rec.truth[keep, 1:3], rec.path)
    ax.plot(tt[keep] - t0, d * 100)
    hw = metrics.get("hardware_mean_distance_cm")
    if hw:
        ax.axhspan(hw[0], hw[1], color="0.85", label=f"real robot mean {hw[0]}-{hw[1]} cm")
    if feas:
        ax.axhline(feas["floor_mean_distance_m"] * 100, color="0.45", lw=1.0,
                   label=f"floor: best turning-limited cut, mean {feas['floor_mean_distance_m'] * 100:.2f} cm")
    if hw or feas:
        ax.legend(fontsize=8)
    ax.set(xlabel="time [s]", ylabel="distance to path [cm]",
           title=f"mean {metrics['mean_distance_m'] * 100:.2f} cm, max {metrics['max_distance_m'] * 100:.2f} cm")
    ax = axes[1, 0]
    st = rec.status[np.isfinite(rec.status[:, 2])] if len(rec.status) else rec.status
    if len(st):
        ts = st[:, 0] - t0
        for j, name in enumerate(("w_a * distance", "w_b * heading", "w_c * (1 - progress)")):
            ax.plot(ts, st[:, 3 + j] * weights[j], label=name)
        ax.plot(ts, st[:, 2], "k", label="total of the chosen branch")
        ax.legend(fontsize=8)
    ax.set(xlabel="time [s]", ylabel="cost (eq. 19)", title="planner cost terms (Fig. S3)")
    ax = axes[1, 1]
    if len(rec.tracked) >= 2:
        e = pose_errors(rec.tracked[:, 0], rec.tracked[:, 1:4], rec.truth[:, 0], rec.truth[:, 1:4])
        ax.plot(e["time_s"] - t0, e["position_error_m"] * 1000, label="position [mm]")
        ax2 = ax.twinx()
        ax2.plot(e["time_s"] - t0, np.degrees(e["heading_error_rad"]), color="tab:red", lw=0.8, label="heading")
        ax2.set_ylabel("heading error [deg]", color="tab:red")
        ax.legend(fontsize=8, loc="upper left")
    ax.set(xlabel="time [s]", ylabel="position error [mm]", title="vision error (tracker vs simulator truth)")
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    plt.close(fig)


def write_video(rec: TwinRecording, mp4, project=None, fps: float = 10.0) -> int:
    """The rendered camera with the path, the tracked pose and the chosen primitive drawn on it.

    ``project(points (N, 3) tank) -> pixels (N, 2)`` places tank points in the preview
    image; without it only the text overlay is drawn. Returns the number of frames.
    """
    import cv2
    if not rec.preview:
        return 0
    first = cv2.imdecode(np.frombuffer(rec.preview[0][1], np.uint8), cv2.IMREAD_COLOR)
    h, w = first.shape[:2]
    out = cv2.VideoWriter(str(mp4), cv2.VideoWriter_fourcc(*"mp4v"), fps, (w, h))
    if not out.isOpened():
        raise RuntimeError(f"cannot write {mp4} (OpenCV has no mp4v writer)")
    path_px = None
    if project is not None and rec.path is not None:
        path_px = np.round(project(np.c_[rec.path, np.zeros(len(rec.path))])).astype(np.int32)
    prim_t = np.array([t for t, _ in rec.primitives])
    tracked_t = rec.tracked[:, 0] if len(rec.tracked) else np.zeros(0)
    n = 0
    for t, data in rec.preview:
        img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
        if img is None or img.shape[:2] != (h, w):
            continue
        if path_px is not None:
            cv2.polylines(img, [path_px.reshape(-1, 1, 2)], False, (0, 200, 255), 1, cv2.LINE_AA)
        if project is not None and len(tracked_t):
            k = int(np.searchsorted(tracked_t, t, side="right")) - 1
            if k >= 0 and t - tracked_t[k] < 0.5:
                x, y, th = rec.tracked[k, 1:4]
                ends = project(np.array([[x, y, 0.0], [x + 0.04 * math.cos(th), y + 0.04 * math.sin(th), 0.0]]))
                a, b = (tuple(int(round(v)) for v in p) for p in ends)
                cv2.circle(img, a, 5, (0, 0, 255), 2, cv2.LINE_AA)
                cv2.arrowedLine(img, a, b, (0, 0, 255), 2, cv2.LINE_AA, tipLength=0.3)
        k = int(np.searchsorted(prim_t, t, side="right")) - 1
        label = rec.primitives[k][1] if k >= 0 else "-"
        cv2.putText(img, f"t {t:6.1f} s  primitive {label}", (10, 24), cv2.FONT_HERSHEY_SIMPLEX, 0.7,
                    (255, 255, 255), 2, cv2.LINE_AA)
        out.write(img)
        n += 1
    out.release()
    return n


def summary_table(results: list[dict]) -> str:
    """The printed table: twin figures beside the real robot's."""
    head = (f"{'path':8s} {'goal':>4} {'time s':>7} {'mean cm':>8} {'max cm':>7} {'real mean cm':>12} "
            f"{'floor cm':>8} {'tight %':>7} {'cm/s':>5} {'real cm/s':>9} {'vision mm':>9} {'vision deg':>10} "
            f"{'latency ms':>10}  primitives")
    rows = [head, "-" * len(head)]
    for m in results:
        hw = m.get("hardware_mean_distance_cm")
        v = m.get("vision") or {}
        lat = m["latency_decision_to_firing"]["median_s"]
        f = m.get("feasibility") or {}
        rows.append(
            f"{m['path']:8s} {'yes' if m['completion_time_s'] is not None else 'no':>4} "
            f"{(m['completion_time_s'] or float('nan')):7.1f} {m['mean_distance_m'] * 100:8.2f} "
            f"{m['max_distance_m'] * 100:7.2f} {(f'{hw[0]}-{hw[1]}' if hw else '-'):>12} "
            f"{f.get('floor_mean_distance_m', math.nan) * 100:8.2f} {f.get('tight_share', math.nan) * 100:7.0f} "
            f"{m['mean_speed_along_path_m_per_s'] * 100:5.2f} {'1.4-2.8':>9} "
            f"{(v.get('position_mean_m', float('nan')) * 1000):9.2f} "
            f"{math.degrees(v.get('heading_mean_rad', float('nan'))):10.2f} "
            f"{(lat * 1000 if lat is not None else float('nan')):10.0f}  {m['primitives_used']}")
    return "\n".join(rows)
