"""``frog-planner-eval``: closed-loop path following on the simulated frog, in one process.

The fast proxy of the twin (no camera, no serial link, no processes): the planner core decides
on the simulator's true pose and twist each period. With ``--twin-seeds`` the simulated robot is
the twin's robot of each seed (limb strengths, kick spread, the tank's yaw torque, as
``frog-twin --seed``); with ``--runs`` the hardware runs' paths are followed too, from their
logged start poses at their decision periods (as ``frog-twin --planner-compare``).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

from frog_planner.core.settings import PathSettings, PlannerSettings, add_arguments, from_arguments
from frog_sim.core.yaw_disturbance import TANK_YAW_TORQUE_SD

EPILOG = """examples:
  frog-planner-eval --library runs/library/default.npz --path all --out runs/eval
  frog-planner-eval --library LIB --path ellipse --depth 2 --metric relative --out runs/eval
  frog-planner-eval --library LIB --compare --out runs/compare     # depths 1-3 x both metrics
  frog-planner-eval --library LIB --path line --lateral-offset 0.05 --out runs/offset
  frog-planner-eval --library LIB --compare --paper-cost --out runs/paper   # the paper's exact eq. 19
  frog-planner-eval --library LIB --path ellipse --transitions simulator --out runs/sim   # batched rollouts
  frog-planner-eval --library LIB --transitions simulator --lead 1.0 --runs ../shared/data/frog/hardware_runs \\
      --twin-seeds 1,2,3 --out runs/sim9      # the twin's robots on all nine paths, decision 1 s after the pose
  frog-planner-eval --library LIB --compare-starts --lead 1.0 --twin-seeds 1,2,3 --out runs/starts
      # rollouts from the robot's estimate against the simulator's full state: table and starts.png

Writes per run <path>[_s<seed>]_d<depth>_<metric>.{json,png,npz} (Fig. 5d-g and S3 style plots)
and a metrics.json summary into --out.
"""


def _cases(args) -> list:
    """The paths followed: the paper's (local frame, started on the path with --lateral-offset),
    then the hardware runs' (--runs)."""
    from frog_twin.core.cases import Case, hardware_cases
    from frog_twin.core.evaluation import PATHS
    names = ["line", "sine", "ellipse"] if args.path == "all" or args.compare else \
        [] if args.path == "none" else [args.path]
    cases = [Case(name, None, None, args.settings.period, args.max_time) for name in names]
    if args.runs is not None:
        cases += hardware_cases(args.runs, args.out / "paths", PathSettings())
    return [(c, PATHS[c.name]() if c.path_settings is None else c.path_settings.build()) for c in cases]


def _run(args, case, path, depth, metric, model_cache, seed=None, start="estimated", rollouts=None):
    import dataclasses

    from frog_planner.core.transition_model import TransitionModel
    from frog_twin.core.evaluation import SimulatorTransitions, run_closed_loop, save_result
    from frog_twin.core.realism import Realism
    settings = dataclasses.replace(args.settings, depth=depth, metric=metric, period=case.period)
    key = (metric, settings.k_neighbours, case.period)
    if key not in model_cache:
        model_cache[key] = TransitionModel.load(args.library, **settings.model_kwargs())
    simulator = (SimulatorTransitions(rollouts, start=start, lead=args.lead, beam=args.beam,
                                      identify=args.identify and start == "estimated", reanchor=args.reanchor,
                                      yaw_torque_sd=args.yaw_torque_sd)
                 if args.transitions == "simulator" else None)
    res = run_closed_loop(path, model_cache[key], settings, start_offset=(0.0, args.lateral_offset, 0.0),
                          max_time=case.duration, transitions=args.transitions, simulator=simulator,
                          realism=None if seed is None else Realism(seed), start_pose=case.start_pose)
    m = res.metrics
    m["path"], m["seed"] = case.name, seed
    tag = "" if args.transitions == "library" else f"_{start}"
    files = save_result(res, args.out, f"{case.name}{'' if seed is None else f'_s{seed}'}_d{depth}_{metric}{tag}")
    if simulator is not None and simulator.identification is not None:
        m["limb_strength_estimate"] = simulator.identification.strengths
    print(f"{case.name:8s} {'' if seed is None else f's{seed} '}depth {depth} {m['metric']:9s}: "
          f"goal {'yes' if m['goal_reached'] else 'NO '} t={m['completion_time_s'] or float('nan'):6.1f} s  "
          f"mean {100 * m['mean_distance_m']:5.2f} cm  max {100 * m['max_distance_m']:5.2f} cm  "
          f"speed {100 * m['mean_speed_along_path_m_per_s']:4.2f} cm/s  prims {m['primitives_used']}", flush=True)
    return {**m, **files}


def plot_starts(rows, png) -> None:
    """Mean distance per path from the estimated start against the exact one (each seed a point)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    names = list(dict.fromkeys(r["path"] for r in rows))
    fig, ax = plt.subplots(figsize=(9, 4.8))
    for j, start in enumerate(("exact", "estimated")):
        for i, name in enumerate(names):
            vals = [100 * r["mean_distance_m"] for r in rows if r["path"] == name and r["start"] == start]
            x = i + (j - 0.5) * 0.3
            ax.bar(x, np.mean(vals), width=0.28, color=("tab:green", "tab:blue")[j],
                   label=None if i else f"{start} start")
            ax.plot([x] * len(vals), vals, "k.", ms=4)
    ax.set_xticks(range(len(names)), names)
    ax.set_ylabel("mean distance to the path [cm]")
    ax.set_title("rollouts from the robot's estimate (pose, twist, firing times) vs the simulator's full state")
    ax.legend()
    fig.tight_layout()
    fig.savefig(png, dpi=120)
    plt.close(fig)


def _starts_table(rows) -> str:
    names = list(dict.fromkeys(r["path"] for r in rows))
    mean = {(n, s): float(np.mean([r["mean_distance_m"] for r in rows if r["path"] == n and r["start"] == s]))
            for n in names for s in ("exact", "estimated")}
    lines = ["| path | exact start cm | estimated start cm | estimated / exact |", "|---|---|---|---|"]
    for n in names:
        lines.append(f"| {n} | {100 * mean[n, 'exact']:.2f} | {100 * mean[n, 'estimated']:.2f} | "
                     f"{mean[n, 'estimated'] / mean[n, 'exact']:.2f} |")
    se, ss = sum(mean[n, "exact"] for n in names), sum(mean[n, "estimated"] for n in names)
    lines.append(f"| **sum** | **{100 * se:.2f}** | **{100 * ss:.2f}** | **{ss / se:.2f}** |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="frog-planner-eval", description=__doc__, epilog=EPILOG,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--library", type=Path, required=True, help="motion library (.npz)")
    ap.add_argument("--path", choices=["line", "sine", "ellipse", "all", "none"], default="all",
                    help="the paper's path(s) to follow (none: only --runs)")
    ap.add_argument("--runs", type=Path, default=None,
                    help="also follow each hardware run's path (a folder of <run>.csv + <run>_path.csv) from its "
                         "logged start pose at its decision period")
    add_arguments(ap, PlannerSettings)
    ap.add_argument("--paper-cost", action="store_true",
                    help="the paper's exact planner: eq. 19 at the leaf, depth 1, tangent heading, weights 500/50/300, "
                         "nearest-state transitions (overrides the depth, weight, look-ahead and correction options; "
                         "--compare still varies the depth)")
    ap.add_argument("--transitions", choices=["library", "simulator"], default="library",
                    help="predictions of the search: the library (paper) or the simulator's batched rollouts "
                         "(depth <= 2)")
    ap.add_argument("--rollout-start", choices=["estimated", "exact"], default="estimated",
                    help="transitions simulator: rollouts from what the robot knows (pose, twist, firing times; "
                         "planner_node's) or from the simulator's full state")
    ap.add_argument("--lead", type=float, default=0.0,
                    help="transitions simulator: the decision is executed this long after its pose [s] "
                         "(planner_node: decision_deadline x period, 1.0 s at its defaults)")
    ap.add_argument("--beam", type=int, default=0, help="depth 2: roll out only this many first primitives (0: all)")
    ap.add_argument("--reanchor", action=argparse.BooleanOptionalAction, default=True,
                    help="transitions simulator with a lead: decide at the execution on the pose tracked then, the "
                         "tree chained from it (planner_node's reanchor)")
    ap.add_argument("--identify", action=argparse.BooleanOptionalAction, default=True,
                    help="transitions simulator from the estimated start: learn the robot's limb strengths from "
                         "its motion and roll out with them (rollout_node's identify_limbs)")
    ap.add_argument("--yaw-torque-sd", type=float, default=TANK_YAW_TORQUE_SD,
                    help="with --identify: also estimate the tank's yaw torque of this stationary sd [N m] and "
                         "roll out with it (rollout_node's yaw_torque_sd; default %(default)s); 0 = assume none")
    ap.add_argument("--twin-seeds", default=None,
                    help="comma-separated seeds: the twin's robot of each (limb strengths, kick spread, yaw "
                         "torque, as frog-twin --seed); default the nominal robot")
    ap.add_argument("--compare-starts", action="store_true",
                    help="transitions simulator from the estimated and from the exact start on each path and "
                         "seed: table and starts.png")
    ap.add_argument("--threads", type=int, default=1, help="rollout threads")
    ap.add_argument("--lateral-offset", type=float, default=0.0, help="start offset left of the path [m]")
    ap.add_argument("--max-time", type=float, default=None, help="give up after [s]")
    ap.add_argument("--turning", action="store_true",
                    help="also measure how the simulated frog turns (sustained E, G, C: steady circle, yaw "
                         "rise time, side-slip; about a minute)")
    ap.add_argument("--compare", action="store_true", help="depths 1-3 x both metrics on every path")
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args(argv)
    try:
        args.settings = from_arguments(PlannerSettings, args)
        if args.paper_cost:
            args.settings = PlannerSettings.paper(period=args.settings.period, metric=args.settings.metric,
                                                  k_neighbours=args.settings.k_neighbours)
        seeds = [None] if args.twin_seeds is None else [int(s) for s in args.twin_seeds.split(",")]
    except ValueError as exc:
        ap.error(str(exc))
    if any(s is not None and s < 0 for s in seeds):
        ap.error(f"--twin-seeds {args.twin_seeds}: seeds are >= 0")
    if not (math.isfinite(args.lead) and 0.0 <= args.lead < args.settings.period):
        ap.error(f"--lead {args.lead}: expected 0 <= lead < the period ({args.settings.period} s)")
    if not 0 <= args.beam <= 9 or not 1 <= args.threads <= 64:
        ap.error(f"--beam {args.beam} --threads {args.threads}: expected a beam of 0-9 and 1-64 threads")
    if args.compare_starts:
        args.transitions = "simulator"
    from frog_common.motion_library_file import LibraryFormatError
    try:
        cases = _cases(args)
    except (ValueError, OSError) as exc:
        print(f"frog-planner-eval: error: {exc}", file=sys.stderr)
        return 2
    if not cases:
        ap.error("nothing to follow: --path none needs --runs")
    if args.compare and args.transitions == "simulator":
        runs = [(d, args.settings.metric) for d in (1, 2)]
    elif args.compare:
        runs = [(d, m) for m in ("euclidean", "relative") for d in (1, 2, 3)]
    else:
        runs = [(args.settings.depth, args.settings.metric)]
    starts = ("exact", "estimated") if args.compare_starts else (args.rollout_start,)
    cache: dict = {}
    rollouts = None
    if args.transitions == "simulator":
        from frog_sim.core.rollouts import Rollouts
        rollouts = Rollouts(threads=args.threads)
    results = []
    try:
        for depth, metric in runs:
            for case, path in cases:
                for seed in seeds:
                    for start in starts:
                        r = _run(args, case, path, depth, metric, cache, seed, start, rollouts)
                        results.append({**r, "start": start if args.transitions == "simulator" else None})
    except (LibraryFormatError, ValueError, OSError) as exc:
        print(f"frog-planner-eval: error: {exc}", file=sys.stderr)
        return 2
    finally:
        if rollouts is not None:
            rollouts.close()
    from frog_twin.core.evaluation import path_min_radius
    radii = {case.name: path_min_radius(path) for case, path in cases}
    for r in results:
        r["path_min_radius_m"] = radii[r["path"]]
    if args.turning:
        from frog_twin.core.evaluation import turning_response
        print("\nturning response, each primitive repeated every period from rest for 45 s:")
        print(f"  {'prim':4s} {'steady COM circle cm':>20} {'speed cm/s':>10} {'yaw deg/s':>9} "
              f"{'63% yaw after s':>15} {'max side-slip deg':>17}")
        for prim in ("E", "G", "C"):
            tr = turning_response(prim, period=args.settings.period)
            print(f"  {prim:4s} {100 * tr.steady_radius:20.1f} {100 * tr.steady_speed:10.2f} "
                  f"{np.degrees(tr.steady_yaw_rate):9.1f} {tr.rise_time:15.1f} {np.degrees(tr.max_course_lag):17.0f}")
        for name, radius in radii.items():
            print(f"  path {name:8s} smallest radius {100 * radius:6.1f} cm")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "metrics.json").write_text(json.dumps(results, indent=1, default=float))
    if len(results) > 1:
        print(f"\n{'path':8s} {'seed':>4} {'depth':>5} {'metric':>20} {'goal':>5} {'time s':>7} {'mean cm':>8} "
              f"{'max cm':>7} {'cm/s':>6}")
        for r in results:
            print(f"{r['path']:8s} {'-' if r['seed'] is None else r['seed']:>4} {r['depth']:5d} {r['metric']:>20} "
                  f"{str(r['goal_reached']):>5} {(r['completion_time_s'] or float('nan')):7.1f} "
                  f"{100 * r['mean_distance_m']:8.2f} {100 * r['max_distance_m']:7.2f} "
                  f"{100 * r['mean_speed_along_path_m_per_s']:6.2f}")
        total = sum(r["mean_distance_m"] for r in results) / max(1, len(seeds) * len(starts) * len(runs))
        print(f"sum over paths of the mean distance (mean over seeds): {100 * total:.2f} cm")
    if args.compare_starts:
        table = _starts_table(results)
        (args.out / "starts.md").write_text(table + "\n")
        plot_starts(results, args.out / "starts.png")
        print("\n" + table + f"\n\nwrote {args.out / 'starts.png'}")
    print(f"\nwrote {args.out / 'metrics.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
