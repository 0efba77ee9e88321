"""Main job: the simulated frog swimming a gait, as a real node graph, recorded and plotted.

Starts ``sim_node`` (frog_sim) and ``recorder`` (frog_logger) as separate processes on an
isolated ROS domain, lets the frog swim for ``--duration`` simulated seconds, stops both
cleanly, then reads the MCAP recording back and writes

    runs/main_<date>_<time>/recording/sim_000.mcap   the log (Foxglove / mcap tools / frog-log)
    runs/main_<date>_<time>/swim.png                 COM path with rod snapshots, speed, heading
    runs/main_<date>_<time>/summary.json             figures of the run, with units

(The planner issue turns this into the closed loop on a reference path.)

Examples
--------
./dev main                                   # 10 % EGaIn, 1.0 Hz, phase 0.5, 20 s
./dev main --frequency 0.6 --duration 30     # another measured gait frequency
./dev main --real-time-factor 3              # faster than real time
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
from ros_harness import NodeProcess, acquire_domain, ros_args  # noqa: E402


def run_graph(args, out: Path) -> Path:
    from tqdm import tqdm
    domain = acquire_domain()
    procs = []
    try:
        rec_dir = out / "recording"
        recorder = NodeProcess(
            ["recorder", *ros_args({"output_dir": str(rec_dir), "file_prefix": "sim",
                                    "topics": ["/frog/sim/odom", "/frog/sim/shape",
                                               "/frog/primitive", "/diagnostics"]})],
            domain.env, out / "recorder.log", "recorder")
        procs.append(recorder)
        recorder.wait_for_log("recording topics", 30)
        sim = NodeProcess(
            ["sim_node", *ros_args({"gait_frequency_hz": args.frequency,
                                    "gait_phase_offset": args.phase,
                                    "model.egain_vol_pct": args.egain,
                                    "real_time_factor": args.real_time_factor,
                                    "duration_s": args.duration})],
            domain.env, out / "sim_node.log", "sim_node")
        procs.append(sim)
        sim.wait_for_log("simulating the frog", 120)
        wall = args.duration / args.real_time_factor
        with tqdm(total=round(wall), unit="s", desc="swimming (wall time)") as bar:
            t0 = time.monotonic()
            while time.monotonic() - t0 < wall + 1.0:
                time.sleep(0.5)
                bar.n = min(round(time.monotonic() - t0), bar.total)
                bar.refresh()
                if not sim.running():
                    raise RuntimeError(f"sim_node exited early:\n{sim.log_text()[-3000:]}")
        for p in reversed(procs):
            code = p.stop()
            if code != 0:
                print(f"warning: {p.name} exited with {code}; log: {p.log_path}")
    finally:
        for p in procs:
            if p.running():
                p.stop()
        domain.release()
    files = sorted(rec_dir.glob("sim_*.mcap"))
    if not files:
        raise RuntimeError(f"no recording in {rec_dir}; see {out}/recorder.log")
    return files[0]


def analyse(mcap: Path, out: Path, args) -> dict:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from frog_logger.core.log_files import read_messages

    t, x, y, yaw, vx, vy, wz = [], [], [], [], [], [], []
    shapes = []
    for topic, _, m in read_messages(mcap, ["/frog/sim/odom", "/frog/sim/shape"]):
        stamp = m.header.stamp.sec + m.header.stamp.nanosec * 1e-9
        if topic == "/frog/sim/odom":
            q = m.pose.pose.orientation
            t.append(stamp)
            x.append(m.pose.pose.position.x)
            y.append(m.pose.pose.position.y)
            yaw.append(2 * math.atan2(q.z, q.w))
            vx.append(m.twist.twist.linear.x)
            vy.append(m.twist.twist.linear.y)
            wz.append(m.twist.twist.angular.z)
        else:
            shapes.append((stamp, np.array([[p.x, p.y] for p in m.points])))
    if len(t) < 10:
        raise RuntimeError(f"only {len(t)} odometry messages in {mcap}")
    t = np.array(t) - t[0]
    x, y = np.array(x), np.array(y)
    yaw = np.unwrap(np.array(yaw))
    vx = np.array(vx)
    steady = t >= min(3.0 / args.frequency, 0.5 * t[-1])
    direction = np.array([math.cos(yaw[0]), math.sin(yaw[0])])
    dist = (np.c_[x, y] - [x[0], y[0]]) @ direction
    speed = float(np.polyfit(t[steady], dist[steady], 1)[0])
    cycles = t[-1] * args.frequency
    summary = {
        "duration_s": float(t[-1]),
        "odometry_messages": int(len(t)),
        "gait": {"frequency_hz": args.frequency, "phase_offset": args.phase,
                 "egain_vol_pct": args.egain},
        "distance_m": float(math.hypot(x[-1] - x[0], y[-1] - y[0])),
        "steady_forward_speed_m_per_s": speed,
        "yaw_drift_deg_per_10_cycles": float(math.degrees(yaw[-1] - yaw[0]) * 10 / cycles),
        "recording": str(mcap),
    }

    fig, axes = plt.subplots(1, 2, figsize=(13, 5.5), gridspec_kw={"width_ratios": [1.3, 1]})
    ax = axes[0]
    every = max(1, len(shapes) // 8)
    for k, (ts, pts) in enumerate(shapes[::every]):
        seg = pts.reshape(-1, 2, 2)
        for a, b in seg:
            ax.plot([a[0] * 100, b[0] * 100], [a[1] * 100, b[1] * 100], color="tab:green",
                    alpha=0.25 + 0.75 * k / max(1, len(shapes[::every]) - 1), lw=1)
    ax.plot(x * 100, y * 100, color="k", lw=1.5, label="centre of mass")
    ax.set_aspect("equal")
    ax.set_xlabel("x [cm] (tank frame)")
    ax.set_ylabel("y [cm]")
    ax.set_title(f"simulated frog, {args.egain:g} % EGaIn, {args.frequency:g} Hz, "
                 f"phase {args.phase:g}\n(rod snapshots every {every / 10:g} s from "
                 f"the start)")
    ax.legend(loc="best")
    ax = axes[1]
    ax.plot(t, vx * 100, lw=1, label="forward velocity (body x)")
    ax.axhline(speed * 100, color="k", ls="--",
               label=f"steady mean speed {speed * 100:.2f} cm/s")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("velocity [cm/s]")
    ax2 = ax.twinx()
    ax2.plot(t, np.degrees(yaw - yaw[0]), color="tab:red", lw=1, label="heading change")
    ax2.set_ylabel("heading change [deg]", color="tab:red")
    ax.legend(loc="upper left")
    ax.set_title("forward velocity and heading")
    fig.tight_layout()
    fig.savefig(out / "swim.png", dpi=120)
    plt.close(fig)
    summary["plot"] = str(out / "swim.png")
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    return summary


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--duration", type=float, default=20.0, help="simulated seconds (default 20)")
    ap.add_argument("--frequency", type=float, default=1.0, help="gait frequency [Hz]")
    ap.add_argument("--phase", type=float, default=0.5, help="rear-pair phase offset [0, 1)")
    ap.add_argument("--egain", type=float, default=10.0, help="EGaIn volume %% of the limbs")
    ap.add_argument("--real-time-factor", type=float, default=1.0)
    ap.add_argument("--out", type=Path, default=None, help="run folder (default runs/main_<time>)")
    args = ap.parse_args(argv)
    if not (args.duration > 0 and args.real_time_factor > 0):
        ap.error("--duration and --real-time-factor must be > 0")
    out = args.out or ROOT / "runs" / time.strftime("main_%Y%m%d_%H%M%S")
    out.mkdir(parents=True, exist_ok=True)
    mcap = run_graph(args, out)
    summary = analyse(mcap, out, args)
    print(json.dumps(summary, indent=2))
    print(f"\nplot: {summary['plot']}\nlog:  {mcap}  (frog-log info {mcap})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
