"""Main job: the frog following a path in closed loop on the simulated robot, as a node graph.

Starts ``sim_node`` (frog_sim; its ground truth is also published as ``/frog/odom``),
``planner_node`` (frog_planner) and ``recorder`` (frog_logger) as separate processes on an
isolated ROS domain, runs until the planner reports the goal (or ``--max-time``), stops
everything cleanly, and writes, from the MCAP recording:

    runs/main_<date>_<time>/recording/loop_000.mcap   the log (Foxglove / mcap tools / frog-log)
    runs/main_<date>_<time>/closed_loop.png           path over the reference, distance, cost terms
    runs/main_<date>_<time>/metrics.json              tracking metrics, with units

On first use it generates the default motion library (200 initial states x 9 primitives,
3 s horizon; a few minutes on 2 cores) into runs/library/frog_default.npz.

Examples
--------
./dev main                                   # line path, from the path start
./dev main --path ellipse --lateral-offset 0.02
./dev main --path sine --real-time-factor 3  # faster than real time (sim publishes /clock)
./dev main --mode gait --frequency 1.0       # open loop: swim a gait (no planner)
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import sys
import time
from pathlib import Path

from frog_planner.core.settings import PathSettings, PlannerSettings, add_arguments, as_dict, from_arguments
from soft_robot_common.processes import NodeProcess, acquire_domain, ros_args

ROOT = Path(__file__).resolve().parents[1]

DEFAULT_LIBRARY = ROOT / "runs" / "library" / "frog_default.npz"
TOPICS = ["/frog/sim/odom", "/frog/sim/shape", "/frog/primitive", "/frog/planner/status",
          "/frog/path", "/diagnostics"]


def ensure_library(path: Path, states: int) -> Path:
    if path.exists():
        return path
    print(f"generating the default motion library on first use: {states} states x 9 primitives "
          f"-> {path}", flush=True)
    path.parent.mkdir(parents=True, exist_ok=True)
    proc = NodeProcess(["frog-library", "generate", "--states", str(states), "--horizon", "3.0",
                        "--out", str(path)], dict(os.environ), path.with_suffix(".log"), "library")
    while proc.running():
        time.sleep(2.0)
        tail = re.findall(r"(\d+)/(\d+) \[", proc.log_text()[-400:])
        if tail:
            print(f"\r  library states {tail[-1][0]}/{tail[-1][1]}", end="", flush=True)
    print()
    if proc.proc.returncode != 0 or not path.exists():
        raise RuntimeError(f"library generation failed:\n{proc.log_text()[-3000:]}")
    return path


def start_graph(args, out: Path, domain, planner: bool):
    import numpy as np

    from frog_twin.core.evaluation import PATHS
    procs = []
    rec = NodeProcess(["recorder", *ros_args({"output_dir": str(out / "recording"),
                                              "file_prefix": "loop", "topics": TOPICS})],
                      domain.env, out / "recorder.log", "recorder")
    procs.append(rec)
    rec.wait_for_log("recording topics", 30)
    sim_params = {"real_time_factor": args.real_time_factor,
                  "publish_clock": args.real_time_factor != 1.0,
                  "model.egain_vol_pct": args.egain}
    if planner:
        path = PATHS[args.path_type]()
        h0 = float(path.tangent_headings[0])
        x0 = path.points[0] + args.lateral_offset * np.array([-math.sin(h0), math.cos(h0)])
        sim_params.update({"odom_alias_topic": "frog/odom", "initial_x": float(x0[0]),
                           "initial_y": float(x0[1]), "initial_heading": h0})
    else:
        sim_params.update({"gait_frequency_hz": args.frequency, "gait_phase_offset": args.phase})
    sim = NodeProcess(["sim_node", *ros_args(sim_params)], domain.env, out / "sim_node.log",
                      "sim_node")
    procs.append(sim)
    sim.wait_for_log("simulating the frog", 120)
    if planner:
        pl = NodeProcess(["planner_node", *ros_args({
            "library_file": str(args.library), **as_dict(args.settings), **as_dict(args.path_settings),
            "use_sim_time": args.real_time_factor != 1.0})],
            domain.env, out / "planner_node.log", "planner_node")
        procs.append(pl)
        pl.wait_for_log("following a", 60)
    return procs


class StatusWatch:
    """Follows ``/frog/planner/status`` on the run's domain: has the planner reached the goal?"""

    def __init__(self, domain):
        import rclpy
        from rclpy.node import Node
        from soft_robot_interfaces.msg import PlannerStatus
        os.environ.update({k: domain.env[k] for k in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE")})
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = Node("main_job_watch", context=self.context)
        self.goal_state = PlannerStatus.STATE_GOAL_REACHED
        self.last = None
        self.node.create_subscription(PlannerStatus, "/frog/planner/status", self._on_status, 10)
        self.executor = rclpy.executors.SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def _on_status(self, msg) -> None:
        self.last = msg

    def goal_reached(self, seconds: float) -> bool:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=max(0.0, min(0.1, end - time.monotonic())))
        return self.last is not None and self.last.state == self.goal_state

    def close(self) -> None:
        import rclpy
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)


def run(args, out: Path, planner: bool) -> Path:
    from tqdm import tqdm
    domain = acquire_domain()
    procs = []
    watch = StatusWatch(domain) if planner else None
    try:
        procs = start_graph(args, out, domain, planner)
        limit = (args.max_time if planner else args.duration) / args.real_time_factor
        t0 = time.monotonic()
        with tqdm(total=round(limit), unit="s", desc="closed loop (wall s)" if planner
                  else "swimming (wall s)") as bar:
            while time.monotonic() - t0 < limit:
                reached = watch.goal_reached(0.5) if watch else time.sleep(0.5)
                bar.n = min(round(time.monotonic() - t0), bar.total)
                bar.refresh()
                for p in procs:
                    if not p.running():
                        raise RuntimeError(f"{p.name} exited early:\n{p.log_text()[-3000:]}")
                if reached:
                    bar.set_description("goal reached")
                    break
        time.sleep(1.0)
        for p in reversed(procs):
            if p.stop() != 0:
                print(f"warning: {p.name} exited with {p.proc.returncode}; log {p.log_path}")
    finally:
        for p in procs:
            if p.running():
                p.stop()
        if watch is not None:
            watch.close()
        domain.release()
    files = sorted((out / "recording").glob("loop_*.mcap"))
    if not files:
        raise RuntimeError(f"no recording in {out / 'recording'}; see {out}/recorder.log")
    return files[0]


def read_recording(mcap: Path) -> dict:
    import numpy as np

    from frog_logger.core.log_files import read_messages
    odom, status, prims, path, shapes = [], [], [], None, []
    for topic, _, m in read_messages(mcap):
        if topic in ("/frog/sim/odom", "/frog/primitive", "/frog/planner/status", "/frog/sim/shape"):
            t = m.header.stamp.sec + m.header.stamp.nanosec * 1e-9
        if topic == "/frog/sim/odom":
            q = m.pose.pose.orientation
            odom.append([t, m.pose.pose.position.x, m.pose.pose.position.y,
                         2 * math.atan2(q.z, q.w), m.twist.twist.linear.x])
        elif topic == "/frog/planner/status":
            status.append([t, m.primitive_id, m.total_cost, m.cost_distance, m.cost_heading,
                           m.cost_progress, m.path_progress, m.distance_to_path, m.state])
        elif topic == "/frog/primitive":
            prims.append((t, m.name))
        elif topic == "/frog/path":
            path = np.array([[p.pose.position.x, p.pose.position.y] for p in m.poses])
        elif topic == "/frog/sim/shape":
            shapes.append((t, np.array([[p.x, p.y] for p in m.points])))
    return {"odom": np.array(odom), "status": np.array(status), "primitives": prims,
            "path": path, "shapes": shapes}


def analyse_closed_loop(mcap: Path, out: Path, args) -> dict:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from frog_twin.core.metrics import distance_to_polyline, samples_before_finish
    rec = read_recording(mcap)
    odom, status, path = rec["odom"], rec["status"], rec["path"]
    if len(odom) < 10 or path is None:
        raise RuntimeError(f"recording {mcap} lacks odometry or the path")
    t0 = odom[0, 0]
    from soft_robot_interfaces.msg import PlannerStatus
    goal = bool(len(status)) and bool(np.any(status[:, 8] == PlannerStatus.STATE_GOAL_REACHED))
    if goal:
        status = status[:int(np.argmax(status[:, 8] == PlannerStatus.STATE_GOAL_REACHED)) + 1]
    if goal:  # the run ends at the goal; the robot coasting on afterwards is not tracking
        odom = odom[odom[:, 0] <= status[-1, 0] + 1e-6]
    odom = odom[:samples_before_finish(odom[:, 1:3], path)]
    t = odom[:, 0] - t0
    dist = distance_to_polyline(odom[:, 1:3], path)
    active = [p for p in rec["primitives"] if p[1] != "I"]
    end_t = (status[-1, 0] - t0) if goal else t[-1]
    progress = float(status[-1, 6]) if len(status) else 0.0
    length = float(np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1)))
    from collections import Counter
    metrics = {
        "path": args.path_type, "path_length_m": length, "planner_settings": as_dict(args.settings),
        "library": str(args.library), "goal_reached": goal,
        "completion_time_s": float(end_t) if goal else None, "final_progress": progress,
        "mean_distance_m": float(dist.mean()), "max_distance_m": float(dist.max()),
        "mean_speed_along_path_m_per_s": progress * length / end_t if end_t > 0 else 0.0,
        "primitives_used": dict(Counter(n for _, n in active)),
        "decisions": len(status), "recording": str(mcap),
        "units": {"distance": "m", "time": "s", "speed": "m/s"},
    }
    fig, axes = plt.subplots(1, 3, figsize=(18, 5.5), gridspec_kw={"width_ratios": [1.6, 1, 1]})
    ax = axes[0]
    every = max(1, len(rec["shapes"]) // 12)
    for _, pts in rec["shapes"][::every]:
        seg = pts.reshape(-1, 2, 2) * 100
        ax.plot(seg[:, :, 0].T, seg[:, :, 1].T, color="tab:green", alpha=0.25, lw=0.8)
    ax.plot(path[:, 0] * 100, path[:, 1] * 100, "k--", lw=1.2, label="reference path")
    ax.plot(odom[:, 1] * 100, odom[:, 2] * 100, color="tab:blue", lw=1.6, label="robot centre of mass")
    ax.plot(*(path[-1] * 100), "r*", ms=13, label="goal")
    ax.set_aspect("equal")
    ax.set(xlabel="x [cm] (tank)", ylabel="y [cm]",
           title=f"{args.path_type}: closed loop, T = {args.settings.period} s, depth {args.settings.depth}")
    ax.legend(fontsize=8)
    ax = axes[1]
    ax.plot(t, dist * 100)
    ax.set(xlabel="time [s]", ylabel="distance to path [cm]",
           title=f"mean {metrics['mean_distance_m'] * 100:.2f} cm, max {metrics['max_distance_m'] * 100:.2f} cm")
    ax = axes[2]
    if len(status):
        ts = status[:, 0] - t0
        cw = args.settings.weights
        w = (cw.distance, cw.heading, cw.progress)   # the weights this run used (NaN rows: no decision)
        for j, name in enumerate(("w_a * distance", "w_b * heading", "w_c * (1 - progress)")):
            ax.plot(ts, status[:, 3 + j] * w[j], label=name)
        ax.plot(ts, status[:, 2], "k", label="total of the chosen branch")
        ax.legend(fontsize=8)
    ax.set(xlabel="time [s]", ylabel="cost (eq. 19)", title="planner cost terms")
    fig.tight_layout()
    fig.savefig(out / "closed_loop.png", dpi=120)
    plt.close(fig)
    metrics["plot"] = str(out / "closed_loop.png")
    (out / "metrics.json").write_text(json.dumps(metrics, indent=2) + "\n")
    return metrics


def analyse_gait(mcap: Path, out: Path, args) -> dict:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    rec = read_recording(mcap)
    odom = rec["odom"]
    t = odom[:, 0] - odom[0, 0]
    x, y, yaw = odom[:, 1], odom[:, 2], np.unwrap(odom[:, 3])
    steady = t >= min(3.0 / args.frequency, 0.5 * t[-1])
    direction = np.array([math.cos(yaw[0]), math.sin(yaw[0])])
    dist = (np.c_[x, y] - [x[0], y[0]]) @ direction
    speed = float(np.polyfit(t[steady], dist[steady], 1)[0])
    metrics = {"mode": "gait", "duration_s": float(t[-1]), "frequency_hz": args.frequency,
               "phase_offset": args.phase, "egain_vol_pct": args.egain,
               "steady_forward_speed_m_per_s": speed,
               "yaw_drift_deg_per_10_cycles": float(math.degrees(yaw[-1] - yaw[0]) * 10
                                                    / (t[-1] * args.frequency)),
               "recording": str(mcap)}
    fig, axes = plt.subplots(1, 2, figsize=(13, 5))
    for _, pts in rec["shapes"][::max(1, len(rec["shapes"]) // 8)]:
        seg = pts.reshape(-1, 2, 2) * 100
        axes[0].plot(seg[:, :, 0].T, seg[:, :, 1].T, color="tab:green", alpha=0.3, lw=0.8)
    axes[0].plot(x * 100, y * 100, "k", lw=1.5, label="centre of mass")
    axes[0].set_aspect("equal")
    axes[0].set(xlabel="x [cm]", ylabel="y [cm]",
                title=f"{args.egain:g} % EGaIn, {args.frequency:g} Hz, phase {args.phase:g}")
    axes[1].plot(t, odom[:, 4] * 100, lw=1, label="forward velocity")
    axes[1].axhline(speed * 100, color="k", ls="--", label=f"steady speed {speed * 100:.2f} cm/s")
    axes[1].set(xlabel="time [s]", ylabel="velocity [cm/s]")
    axes[1].legend()
    fig.tight_layout()
    fig.savefig(out / "swim.png", dpi=120)
    plt.close(fig)
    metrics["plot"] = str(out / "swim.png")
    (out / "metrics.json").write_text(json.dumps(metrics, indent=2) + "\n")
    return metrics


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--mode", choices=["closed-loop", "gait"], default="closed-loop")
    ap.add_argument("--path", dest="path_type", choices=["line", "sine", "ellipse"], default="line",
                    help="reference path (paper eq. 15-17)")
    ap.add_argument("--lateral-offset", type=float, default=0.0, help="start left of the path [m]")
    add_arguments(ap, PlannerSettings)
    add_arguments(ap, PathSettings, exclude=("path_type", "path_start_x", "path_start_y", "path_heading",
                                             "waypoint_file"))
    ap.add_argument("--library", type=Path, default=DEFAULT_LIBRARY)
    ap.add_argument("--library-states", type=int, default=200, help="size if generated")
    ap.add_argument("--max-time", type=float, default=90.0, help="simulated seconds at most")
    ap.add_argument("--duration", type=float, default=20.0, help="gait mode: simulated seconds")
    ap.add_argument("--frequency", type=float, default=1.0, help="gait mode: frequency [Hz]")
    ap.add_argument("--phase", type=float, default=0.5, help="gait mode: phase offset")
    ap.add_argument("--egain", type=float, default=10.0, help="EGaIn volume %% of the limbs")
    ap.add_argument("--real-time-factor", type=float, default=1.0)
    ap.add_argument("--out", type=Path, default=None, help="run folder (default runs/main_<time>)")
    args = ap.parse_args(argv)
    if not (args.max_time > 0 and args.duration > 0 and args.real_time_factor > 0):
        ap.error("--max-time, --duration and --real-time-factor must be > 0")
    try:
        args.settings = from_arguments(PlannerSettings, args)
        args.path_settings = from_arguments(PathSettings, args)
    except ValueError as exc:
        ap.error(str(exc))
    out = args.out or ROOT / "runs" / time.strftime("main_%Y%m%d_%H%M%S")
    out.mkdir(parents=True, exist_ok=True)
    if args.mode == "closed-loop":
        if args.library == DEFAULT_LIBRARY:
            ensure_library(args.library, args.library_states)
        elif not args.library.exists():
            ap.error(f"library {args.library} does not exist (frog-library generate --out ...)")
        mcap = run(args, out, planner=True)
        metrics = analyse_closed_loop(mcap, out, args)
    else:
        mcap = run(args, out, planner=False)
        metrics = analyse_gait(mcap, out, args)
    print(json.dumps(metrics, indent=2))
    print(f"\nplot: {metrics['plot']}\nlog:  {mcap}  (frog-log info {mcap})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
