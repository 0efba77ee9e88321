"""``softkin-twin``: the tendon finger's digital twin, end to end through real node processes.

Starts ``marlin_emulator`` (a Marlin board on a pty), ``stepper_driver`` (G-code over that
serial device), ``kinematics_node`` and frog_logger's ``recorder`` as separate processes on an
isolated ROS domain, follows the built-in curves through the ``finger/follow_curve`` action,
stops everything cleanly and writes to ``--out`` (default ``runs/twin_<date>_<time>``):

    fig13_<curve>.png      target vs achieved tip (Fig. 13 style) and the error per waypoint
    errors.png             error curves of all curves
    metrics.json           errors (IK and achieved), timings, chain checks, recording counts; SI units
    recording/twin_000.mcap  every finger topic (Foxglove, mcap tools, frog-log)

*Achieved* is forward kinematics of the motor positions the emulated board really reached at
the end of each waypoint's move (``finger/emulator/move_end``): it includes the IK error, the
microstep quantisation, and anything lost between the nodes.

Examples
--------
  softkin-twin                          # 'L' and 'flame', default finger (resolution 2)
  softkin-twin --curves L --out runs/twin_L
  softkin-twin --cable-speed 0.02 --no-hold-rest-cables
  softkin-twin --port /dev/ttyACM0      # a real Marlin board instead of the emulator (no 'achieved')
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np
from soft_robot_common.graph import load_graph
from soft_robot_common.processes import FASTDDS_TRANSPORTS, acquire_domain

MM = 1e-3
#: The finger's node graph (package data; also installed as share/softkin_fk/config/finger_graph.yaml).
GRAPH_FILE = Path(__file__).resolve().parent / "config" / "finger_graph.yaml"


def finger_graph(args, out: Path, port: str, graph_file=GRAPH_FILE):
    """The finger's processes: the emulated board (sim) or a real one at ``--port`` (real)."""
    overrides = {"recorder": {"output_dir": str(out / "recording")},
                 "stepper_driver": {"port": port, "max_cable_speed": args.cable_speed,
                                    "banner_timeout": 3.0 if args.port else 1.0},
                 "kinematics_node": {"resolution": args.resolution, "config_samples": args.config_samples,
                                     "tolerance": args.lam_mm * MM, "hold_rest_cables": args.hold_rest_cables}}
    if not args.port:
        overrides["marlin_emulator"] = {"port_link": port}
    return load_graph(graph_file, "real" if args.port else "sim", overrides)


def _stamp(msg) -> float:
    return msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec


def run_curves(args, env) -> dict:
    """Send each curve to the action server; collect feedback, results, setpoints and move ends."""
    from rclpy.action import ActionClient
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState
    from soft_robot_common.graph_watch import GraphWatch
    from soft_robot_interfaces.action import FollowCurve
    from tqdm import tqdm

    watch = GraphWatch(int(env["ROS_DOMAIN_ID"]), "softkin_twin")
    node, spin_until = watch.node, watch.spin_until
    qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
    setpoints, ends, motor = [], [], []
    node.create_subscription(JointState, "/finger/tendon_setpoints", setpoints.append, qos)
    node.create_subscription(JointState, "/finger/emulator/move_end", ends.append, qos)
    node.create_subscription(JointState, "/finger/emulator/motor_state", motor.append, qos)
    client = ActionClient(node, FollowCurve, "/finger/follow_curve")

    out = {}
    try:
        spin_until(client.server_is_ready, 120, "the follow_curve action server")
        spin_until(lambda: node.count_publishers("/finger/emulator/move_end") >= (0 if args.port else 1)
                   and node.count_subscribers("/finger/tendon_setpoints") >= 2, 60, "driver and emulator")
        watch.spin_for(0.5)
        for curve in args.curves:
            n0_sp, n0_end = len(setpoints), len(ends)
            feedback = []
            with tqdm(total=None, desc=f"'{curve}' through the action", disable=args.quiet) as bar:
                def on_fb(msg):
                    feedback.append(msg.feedback)
                    bar.total = msg.feedback.total
                    bar.update(1)
                t0 = time.monotonic()
                goal = FollowCurve.Goal(curve=curve, tolerance=args.lam_mm * MM)
                fut = client.send_goal_async(goal, feedback_callback=on_fb)
                spin_until(fut.done, 30, "goal acceptance")
                handle = fut.result()
                if not handle.accepted:
                    raise RuntimeError(f"goal '{curve}' rejected")
                res_fut = handle.get_result_async()
                spin_until(res_fut.done, 600, f"the result of '{curve}'")
                wall = time.monotonic() - t0
            res = res_fut.result().result
            # wait for the motion to end: no new move end and the motors at rest for 1 s
            last = [time.monotonic(), len(ends)]

            def settled():
                if len(ends) != last[1]:
                    last[:] = [time.monotonic(), len(ends)]
                moving = motor and any(abs(v) > 1e-9 for v in motor[-1].velocity)
                return not moving and time.monotonic() - last[0] > 1.0
            t_motion = time.monotonic()
            spin_until(settled if not args.port else (lambda: time.monotonic() - t_motion > 2.0), 300,
                       "the motion to end")
            out[curve] = dict(
                wall_s=wall, motion_after_result_s=time.monotonic() - t_motion - 1.0, result=res,
                feedback_indices=[f.index for f in feedback],
                setpoints=np.array([list(m.position) for m in setpoints[n0_sp:]]),
                setpoint_stamps=np.array([_stamp(m) for m in setpoints[n0_sp:]]),
                move_ends=np.array([list(m.position) for m in ends[n0_end:]]).reshape(-1, 3),
                move_end_stamps=np.array([_stamp(m) for m in ends[n0_end:]]))
    finally:
        client.destroy()
        watch.close()
    return out


def achieved_pulls(setpoints: np.ndarray, move_ends: np.ndarray, steps_per_metre: float):
    """Pull per waypoint where its move ended: one move per setpoint that changes the quantised
    position (the driver skips the others); returns (pulls (N, 3), all moves matched exactly)."""
    q = np.rint(setpoints * steps_per_metre)
    moved = np.ones(len(q), bool)
    moved[1:] = np.any(q[1:] != q[:-1], axis=1)
    out = np.full(setpoints.shape, np.nan)
    k = 0
    prev = None
    for i in range(len(q)):
        if moved[i] and k < len(move_ends):
            prev = move_ends[k]
            k += 1
        if prev is not None:
            out[i] = prev
    exact = k == len(move_ends) == int(moved.sum()) and np.allclose(
        np.rint(out * steps_per_metre), q, atol=0.5)
    return out, bool(exact)


def analyse(args, runs: dict, out: Path) -> dict:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .core.forward import ForwardSolver
    from .core.models import build_tendon_finger
    from .core.stepper import CableMotorMap
    mesh = build_tendon_finger(resolution=args.resolution) if args.resolution else build_tendon_finger()
    fs = ForwardSolver(mesh)
    fs.hold_rest_cables = args.hold_rest_cables
    L = np.array([a.total_length for a in mesh.actuators])
    spm = CableMotorMap().steps_per_metre
    lam = args.lam_mm * MM
    metrics = dict(units="m, s", lambda_m=lam, resolution=mesh.info.get("resolution"),
                   hold_rest_cables=args.hold_rest_cables, cable_speed_m_s=args.cable_speed, curves={})
    fig_e, ax_e = plt.subplots(figsize=(8, 4))
    for curve, r in runs.items():
        res = r["result"]
        targets = np.array([[p.x, p.y, p.z] for p in res.targets])
        ik_tips = np.array([[p.x, p.y, p.z] for p in res.reached])
        ik_err = np.array(res.errors)
        m = dict(waypoints=len(targets), action_wall_s=r["wall_s"], solve_s=res.solve_seconds,
                 motion_after_result_s=r["motion_after_result_s"], feedback_messages=len(r["feedback_indices"]),
                 feedback_every_waypoint=r["feedback_indices"] == list(range(len(targets))),
                 setpoints=len(r["setpoints"]), moves=len(r["move_ends"]), result_message=res.message,
                 ik_error_max_m=float(ik_err.max()), ik_error_mean_m=float(ik_err.mean()),
                 ik_within_lambda=int(np.sum(ik_err <= lam)))
        achieved = None
        if len(r["move_ends"]) and len(r["setpoints"]) == len(targets):
            pulls, exact = achieved_pulls(r["setpoints"], r["move_ends"], spm)
            achieved = np.full_like(targets, np.nan)
            prev = None
            lo = np.array([a.bounds[0] for a in mesh.actuators])
            clipped = 0
            for i, p in enumerate(pulls):
                if np.any(np.isnan(p)):
                    continue
                x0, a0 = (prev.positions, prev.active) if prev is not None else (None, None)
                # a whole microstep can overshoot a cable's model range by < half a step
                s = 1.0 - p / L
                clipped += int(np.any(s < lo))
                prev = fs.solve(np.clip(s, lo, 1.0), x0=x0, active0=a0, tol=1e-8)
                achieved[i] = prev.marker(mesh, "tip")
            err = np.linalg.norm(achieved - targets, axis=1)
            quant = np.abs(pulls - r["setpoints"]).max()
            m.update(chain_exact=exact, achieved_error_max_m=float(np.nanmax(err)),
                     achieved_error_mean_m=float(np.nanmean(err)), achieved_error_median_m=float(np.nanmedian(err)),
                     achieved_error_rms_m=float(np.sqrt(np.nanmean(err ** 2))),
                     achieved_within_lambda=int(np.sum(err <= lam)),
                     achieved_vs_commanded_tip_max_m=float(np.nanmax(np.linalg.norm(achieved - ik_tips, axis=1))),
                     quantisation_max_pull_m=float(quant), clipped_to_model_range=clipped,
                     motion_s=float(r["move_end_stamps"][-1] - r["setpoint_stamps"][0]) if len(r["move_end_stamps"])
                     else None, achieved_errors_m=err.tolist())
        m["ik_errors_m"] = ik_err.tolist()
        metrics["curves"][curve] = m
        fig, (a1, a2) = plt.subplots(1, 2, figsize=(12, 5))
        a1.plot(targets[:, 0] / MM, targets[:, 1] / MM, "r.-", ms=5, lw=1, label="target")
        a1.plot(ik_tips[:, 0] / MM, ik_tips[:, 1] / MM, "b+", ms=6, label="commanded (IK + FK)")
        if achieved is not None:
            a1.plot(achieved[:, 0] / MM, achieved[:, 1] / MM, "k.-", ms=3, lw=0.8,
                    label="achieved (FK of the emulated motors)")
        a1.set_aspect("equal")
        a1.set_xlabel("x (mm)")
        a1.set_ylabel("y (mm)")
        a1.legend(fontsize=8)
        a1.set_title(f"'{curve}': {m.get('achieved_within_lambda', m['ik_within_lambda'])}/{len(targets)} "
                     f"within {args.lam_mm} mm")
        idx = np.arange(1, len(targets) + 1)
        a2.plot(idx, ik_err / MM, "b.-", ms=3, label="IK (commanded)")
        if achieved is not None:
            a2.plot(idx, np.array(m["achieved_errors_m"]) / MM, "k.-", ms=3, label="achieved")
            ax_e.plot(idx, np.array(m["achieved_errors_m"]) / MM, ".-", ms=3, label=f"'{curve}' achieved")
        ax_e.plot(idx, ik_err / MM, ":", label=f"'{curve}' IK")
        a2.axhline(args.lam_mm, color="r", ls="--", label="lambda")
        a2.set_xlabel("waypoint")
        a2.set_ylabel("tip error (mm)")
        a2.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(out / f"fig13_{curve}.png", dpi=120)
        plt.close(fig)
    ax_e.axhline(args.lam_mm, color="r", ls="--", label="lambda")
    ax_e.set_xlabel("waypoint")
    ax_e.set_ylabel("tip error (mm)")
    ax_e.legend(fontsize=8)
    fig_e.tight_layout()
    fig_e.savefig(out / "errors.png", dpi=120)
    plt.close(fig_e)
    return metrics


def recording_counts(folder: Path) -> dict:
    from mcap.reader import make_reader
    counts = {}
    for f in sorted(folder.glob("*.mcap")):
        with open(f, "rb") as fh:
            summary = make_reader(fh).get_summary()
        if summary is None or summary.statistics is None:
            continue
        for cid, n in summary.statistics.channel_message_counts.items():
            topic = summary.channels[cid].topic
            counts[topic] = counts.get(topic, 0) + n
    return counts


def board_preflight(args) -> list[str]:
    """Check the board at ``args.port`` before any node starts; the failures' messages."""
    import serial

    from .core.board_check import check_board
    from .core.stepper import CableMotorMap
    drv = load_graph(GRAPH_FILE, "real")["stepper_driver"].parameters
    m = CableMotorMap(min_pull=drv["min_pull"], max_pull=drv["max_pull"])
    to_units = m.steps_per_metre / m.steps_per_unit
    try:
        io = serial.Serial(args.port, 115200, timeout=0.1)
    except (serial.SerialException, OSError) as exc:
        return [f"cannot open the board's port {args.port}: {exc}"]
    try:
        checks = check_board(io, args.port, m.axes, (m.min_pull * to_units, m.max_pull * to_units), args.zero)
    finally:
        io.close()
    for c in checks:
        print(f"  pre-flight {c.name:9s} {'ok  ' if c.ok else 'FAIL'} {c.message}", flush=True)
    return [c.message for c in checks if not c.ok]


def build_parser():
    p = argparse.ArgumentParser(prog="softkin-twin", description=__doc__.split("\n")[0],
                                epilog=__doc__.split("Examples\n--------\n")[1],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--curves", nargs="+", default=["L", "flame"], help="built-in curves to follow (default: L flame)")
    p.add_argument("--out", default=None, help="output folder (default runs/twin_<date>_<time>)")
    p.add_argument("--resolution", type=int, default=0, help="finger mesh resolution (0 = default, 2)")
    p.add_argument("--config-samples", type=int, default=5, help="configuration samples per cable (default 5)")
    p.add_argument("--lam-mm", type=float, default=0.2, help="IK threshold lambda (mm)")
    p.add_argument("--cable-speed", type=float, default=0.01, help="fastest cable's speed in a move (m/s)")
    p.add_argument("--hold-rest-cables", dest="hold_rest_cables", action="store_true", default=True,
                   help="a cable at rest that bending would stretch is held taut by its motor (default)")
    p.add_argument("--no-hold-rest-cables", dest="hold_rest_cables", action="store_false",
                   help="the core's model: such a cable stays slack (the curves were placed in it)")
    p.add_argument("--port", default=None, help="a real Marlin board's serial port instead of the emulator "
                   "(pre-flight: M115/ok handshake, M114 position, M211 soft endstops, the zero)")
    p.add_argument("--zero", choices=("declared", "home"), default="declared",
                   help="with --port: the cables are at rest now (declared, G92 by the driver) or home the board "
                        "(G28, needs endstops)")
    p.add_argument("--preflight-only", action="store_true", help="with --port: run the board's pre-flight and exit")
    p.add_argument("--domain", type=int, default=None,
                   help="ROS domain id (default: one no other run on this machine holds)")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    from .core.curves import CURVES
    bad = [c for c in args.curves if c not in CURVES]
    if bad:
        print(f"softkin-twin: error: unknown curve(s) {bad}; built-in curves: {sorted(CURVES)}", file=sys.stderr)
        return 2
    if not 0.0 < args.cable_speed <= 1.0 or args.lam_mm <= 0:
        print("softkin-twin: error: --cable-speed must be in (0, 1] m/s and --lam-mm positive", file=sys.stderr)
        return 2
    if args.port:
        failed = board_preflight(args)
        if failed:
            print("softkin-twin: pre-flight failed, nothing was moved:\n" + "\n".join(f"  - {m}" for m in failed),
                  file=sys.stderr)
            return 2
        if args.preflight_only:
            return 0
    elif args.preflight_only:
        print("softkin-twin: error: --preflight-only checks a real board: give --port", file=sys.stderr)
        return 2
    out = Path(args.out or os.path.join("runs", time.strftime("twin_%Y%m%d_%H%M%S")))
    if list((out / "recording").glob("*.mcap")):
        print(f"softkin-twin: error: {out} already holds a recording; choose another --out", file=sys.stderr)
        return 2
    (out / "recording").mkdir(parents=True, exist_ok=True)
    if args.domain is not None:
        domain = None
        env = dict(os.environ, ROS_DOMAIN_ID=str(args.domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
                   PYTHONUNBUFFERED="1", RCUTILS_COLORIZED_OUTPUT="0",
                   FASTDDS_BUILTIN_TRANSPORTS=FASTDDS_TRANSPORTS)
        env.pop("ROS_LOCALHOST_ONLY", None)
    else:
        domain = acquire_domain()     # held exclusively until the end of the run
        env = domain.env
    os.environ.update(ROS_DOMAIN_ID=env["ROS_DOMAIN_ID"], ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    port = args.port or str((out / "marlin_pty").resolve())
    procs = []
    graph = finger_graph(args, out, port)

    from soft_robot_common.graph_watch import GraphWatch
    watch = GraphWatch(int(env["ROS_DOMAIN_ID"]), "softkin_twin_start")

    def start(name, timeout, keys=("ready",)):
        """Start a node and wait until its diagnostics say it is ready (never its log)."""
        pr = graph[name].start(env, out)
        procs.append(pr)
        watch.wait_ready(name, pr.pid, keys=keys, timeout=timeout, procs=procs)

    t_start = time.monotonic()
    try:
        start("recorder", 60, keys=())      # up: it subscribes to the topics once their publishers start
        if not args.port:
            start("marlin_emulator", 60)
        start("stepper_driver", 60)
        start("kinematics_node", 300)
        startup = time.monotonic() - t_start
        watch.close()
        runs = run_curves(args, env)
    finally:
        watch.close()
        codes = {}
        for pr in reversed(procs):
            codes[pr.name] = pr.stop()
        if domain is not None:
            domain.release()
    bad_exit = {k: v for k, v in codes.items() if v != 0}
    if bad_exit:
        print(f"warning: processes did not exit cleanly: {bad_exit} (logs in {out})", file=sys.stderr)
    metrics = analyse(args, runs, out)
    metrics.update(startup_s=startup, exit_codes=codes, recording_message_counts=recording_counts(out / "recording"),
                   domain_id=int(env["ROS_DOMAIN_ID"]), port=port, emulated=not args.port)
    with open(out / "metrics.json", "w") as fh:
        json.dump(metrics, fh, indent=2)
    summary = {c: {k: (round(v / MM, 4) if k.endswith("_m") else v) for k, v in m.items()
                   if k in ("waypoints", "action_wall_s", "ik_error_max_m", "achieved_error_max_m",
                            "achieved_error_mean_m", "achieved_within_lambda", "chain_exact")}
               for c, m in metrics["curves"].items()}
    print(json.dumps(dict(out=str(out), curves_mm=summary, recording=metrics["recording_message_counts"]), indent=1))
    return 0 if not bad_exit else 1


if __name__ == "__main__":
    sys.exit(main())
