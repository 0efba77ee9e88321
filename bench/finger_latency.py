"""kinematics_node latencies: IK/FK service round trips and 'L' through the action.

Starts ``kinematics_node`` (default finger, resolution 2, 5^3 configuration samples) as a
process on an isolated domain and measures, from a client in this process:

* ``ik_1mm`` -- SolveIk round trip for a target 1 mm from the previous one (warm start), a
  walk of 1 mm steps around a 3 mm circle inside the workspace. Target: median <= 50 ms.
  Also the core's ``solve_ik`` alone from the same warm starts (Algorithm 2's line search,
  without the node's one-step Gauss-Newton predictor).
* ``fk`` -- ForwardKinematics round trip for actuations near the previous one.
* ``L_action`` -- the 'L' curve (55 waypoints) through ``finger/follow_curve`` (dry run), goal
  sent -> result received. Target <= 10 s; paper (Algorithm 3 in C++): 38 s.

Each is printed beside the core's own time for the same work, measured in this run in this
process (``RobotKinematics`` with the node's settings): the ratio is the cost of the node
(DDS, serialisation, executor, worker thread). Medians of wall time; CPU time of the node
process (from /proc, all threads) and of this process beside them; the load average first.

    ./dev bench finger_latency [--reps 3] [--steps 30] [--json FILE]
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
from ros_harness import GraphProbe, NodeProcess, acquire_domain  # noqa: E402

TARGET = dict(ik_1mm=0.050, L_action=10.0)
PAPER = dict(L_action=38.0)


def proc_cpu(pid: int) -> float:
    """CPU seconds (user + system, all threads) of a process."""
    with open(f"/proc/{pid}/stat") as fh:
        f = fh.read().rsplit(")", 1)[1].split()
    return (int(f[11]) + int(f[12])) / os.sysconf("SC_CLK_TCK")


def walk(n: int, centre=(0.099, 0.0575), radius=0.003, step=0.001):
    """n targets on a circle, 1 mm apart (chord), in the finger plane."""
    dphi = 2 * np.arcsin(step / (2 * radius))
    return [np.array([centre[0] + radius * np.cos(k * dphi), centre[1] + radius * np.sin(k * dphi), 0.0125])
            for k in range(n + 1)]


def row(name, ours, core, cpu_node, cpu_client, note=""):
    tgt = TARGET.get(name)
    ok = "" if tgt is None else ("MET   " if ours <= tgt else "MISSED")
    paper = f" | paper {PAPER[name]:.1f} s (ours/paper {ours / PAPER[name]:.2f})" if name in PAPER else ""
    tg = f" | target {tgt * 1e3:.0f} ms {ok}" if tgt is not None and tgt < 1 else (
        f" | target {tgt:.1f} s {ok}" if tgt is not None else "")
    print(f"{name:9s} median {ours * 1e3:9.1f} ms | core alone {core * 1e3:9.1f} ms (node/core {ours / core:5.2f}) | "
          f"cpu node {cpu_node * 1e3:8.1f} ms, client {cpu_client * 1e3:7.1f} ms{tg}{paper} {note}", flush=True)
    return dict(name=name, median_s=ours, core_s=core, node_over_core=ours / core, cpu_node_s=cpu_node,
                cpu_client_s=cpu_client, target_s=tgt, met=None if tgt is None else ours <= tgt, note=note)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--reps", type=int, default=3, help="repetitions of the 'L' action (default 3)")
    ap.add_argument("--steps", type=int, default=30, help="1 mm IK steps (default 30)")
    ap.add_argument("--json", default=None, help="also write the rows to this file")
    a = ap.parse_args()
    print(f"load average {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f} {os.getloadavg()[2]:.2f} "
          f"on {os.cpu_count()} cores", flush=True)
    from geometry_msgs.msg import Point
    from rclpy.action import ActionClient
    from soft_robot_interfaces.action import FollowCurve
    from soft_robot_interfaces.srv import ForwardKinematics, SolveIk

    from softkin_fk.core.curves import curve_L
    from softkin_fk.core.kinematics import RobotKinematics
    from softkin_fk.core.models import build_tendon_finger

    domain = acquire_domain()
    os.environ.update(ROS_DOMAIN_ID=domain.env["ROS_DOMAIN_ID"],
                      ROS_AUTOMATIC_DISCOVERY_RANGE=domain.env["ROS_AUTOMATIC_DISCOVERY_RANGE"])
    log = Path("runs") / "bench" / "finger_latency_kinematics_node.log"
    log.parent.mkdir(parents=True, exist_ok=True)
    node = NodeProcess(["kinematics_node"], domain.env, log, "kinematics_node")
    probe = GraphProbe(domain, "finger_bench")
    rows = []
    try:
        node.wait_for_log("ready in", timeout=300)
        pid = node.pid
        ik = probe.node.create_client(SolveIk, "/finger/solve_ik")
        fk = probe.node.create_client(ForwardKinematics, "/finger/forward_kinematics")
        probe.wait_for_service(ik, 30)
        probe.wait_for_service(fk, 30)
        core = RobotKinematics(build_tendon_finger())

        # --- IK, 1 mm steps ------------------------------------------------------------
        targets = walk(a.steps)
        probe.call(ik, SolveIk.Request(target=Point(x=targets[0][0], y=targets[0][1], z=targets[0][2])), 60)
        warm = core.inverse(targets[0])
        times, core_times, errs = [], [], []
        c0, p0 = proc_cpu(pid), time.process_time()
        for t in targets[1:]:
            t0 = time.perf_counter()
            r = probe.call(ik, SolveIk.Request(target=Point(x=t[0], y=t[1], z=t[2])), 60)
            times.append(time.perf_counter() - t0)
            errs.append(r.residual_error)
            assert r.success, r.message
        c1, p1 = proc_cpu(pid), time.process_time()
        q0 = time.process_time()
        for t in targets[1:]:
            t0 = time.perf_counter()
            warm = core.inverse(t, warm=warm)
            core_times.append(time.perf_counter() - t0)
        core_cpu = (time.process_time() - q0) / len(core_times)
        # the core's Algorithm 2 alone (line search from the warm start, no predictor step)
        from softkin_fk.core.inverse import solve_ik
        s = core.settings
        plain, prev = [], core.inverse(targets[0])
        for t in targets[1:]:
            t0 = time.perf_counter()
            prev = solve_ik(core.solver, t, initial=prev.actuation, initial_fk=prev.fk, lam=s.lam, i_max=s.i_max,
                            jacobian=s.jacobian, direction=s.direction, fk_tol=s.fk_tol)
            plain.append(time.perf_counter() - t0)
        n = len(times)
        rows.append(row("ik_1mm", statistics.median(times), statistics.median(core_times), (c1 - c0) / n,
                        (p1 - p0) / n, f"({n} calls, max {max(times) * 1e3:.0f} ms, largest error "
                                       f"{max(errs) * 1e3:.3f} mm; core cpu {core_cpu * 1e3:.1f} ms; core solve_ik "
                                       f"line search alone {statistics.median(plain) * 1e3:.1f} ms)"))

        # --- FK ------------------------------------------------------------------------
        acts = [np.array([0.95, 0.96, 0.97]) - 0.002 * k for k in range(10)]
        times, core_times = [], []
        prev = None
        c0, p0 = proc_cpu(pid), time.process_time()
        for act in acts:
            t0 = time.perf_counter()
            r = probe.call(fk, ForwardKinematics.Request(actuation=act.tolist()), 60)
            times.append(time.perf_counter() - t0)
        c1, p1 = proc_cpu(pid), time.process_time()
        for act in acts:
            t0 = time.perf_counter()
            core.forward(act)
            core_times.append(time.perf_counter() - t0)
        rows.append(row("fk", statistics.median(times), statistics.median(core_times), (c1 - c0) / len(acts),
                        (p1 - p0) / len(acts), "(cold FK from rest in both)"))
        del prev

        # --- 'L' through the action ------------------------------------------------------
        client = ActionClient(probe.node, FollowCurve, "/finger/follow_curve")
        probe.spin_until(client.server_is_ready, 30, "action server")
        walls, cpus, cpc, core_times, errs = [], [], [], [], []
        for _ in range(a.reps):
            c0, p0 = proc_cpu(pid), time.process_time()
            t0 = time.perf_counter()
            fut = client.send_goal_async(FollowCurve.Goal(curve="L", dry_run=True))
            probe.spin_until(fut.done, 30, "goal accepted")
            res_fut = fut.result().get_result_async()
            probe.spin_until(res_fut.done, 300, "result")
            walls.append(time.perf_counter() - t0)
            cpus.append(proc_cpu(pid) - c0)
            cpc.append(time.process_time() - p0)
            errs.append(max(res_fut.result().result.errors))
        P = curve_L()
        for _ in range(a.reps):
            t0 = time.perf_counter()
            tr = core.follow(P)
            core_times.append(time.perf_counter() - t0)
        rows.append(row("L_action", statistics.median(walls), statistics.median(core_times), statistics.median(cpus),
                        statistics.median(cpc), f"({a.reps} runs; largest error {max(errs) * 1e3:.3f} mm, core "
                                                f"{tr.errors.max() * 1e3:.3f} mm)"))
    finally:
        probe.close()
        code = node.stop()
        domain.release()
    print(f"kinematics_node exit code {code}; load average now {os.getloadavg()[0]:.2f}")
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(dict(rows=rows, load_average=os.getloadavg()), fh, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
