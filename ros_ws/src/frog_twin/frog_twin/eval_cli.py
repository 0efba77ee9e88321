"""``frog-planner-eval``: closed-loop path following on the simulated frog, in one process."""

from __future__ import annotations

import argparse
import json
import sys

from pathlib import Path

import numpy as np

from frog_planner.core.settings import PlannerSettings, add_arguments, from_arguments

EPILOG = """examples:
  frog-planner-eval --library runs/library/default.npz --path all --out runs/eval
  frog-planner-eval --library LIB --path ellipse --depth 2 --metric relative --out runs/eval
  frog-planner-eval --library LIB --compare --out runs/compare     # depths 1-3 x both metrics
  frog-planner-eval --library LIB --path line --lateral-offset 0.05 --out runs/offset
  frog-planner-eval --library LIB --compare --paper-cost --out runs/paper   # the paper's exact eq. 19
  frog-planner-eval --library LIB --path ellipse --transitions simulator --out runs/oracle  # exact predictions

Writes per run <path>_d<depth>_<metric>.{json,png,npz} (Fig. 5d-g and S3 style plots) and
a metrics.json summary into --out.
"""


def _run(args, path_name, depth, metric, model_cache):
    import dataclasses

    from frog_planner.core.transition_model import TransitionModel
    from frog_twin.core.evaluation import PATHS, run_closed_loop, save_result
    settings = dataclasses.replace(args.settings, depth=depth, metric=metric)
    key = (metric, settings.k_neighbours)
    if key not in model_cache:
        model_cache[key] = TransitionModel.load(args.library, **settings.model_kwargs())
    path = PATHS[path_name]()
    res = run_closed_loop(path, model_cache[key], settings, start_offset=(0.0, args.lateral_offset, 0.0),
                          max_time=args.max_time, transitions=args.transitions)
    files = save_result(res, args.out)
    m = res.metrics
    print(f"{path_name:8s} depth {depth} {metric:9s}: goal {'yes' if m['goal_reached'] else 'NO '} "
          f"t={m['completion_time_s'] or float('nan'):6.1f} s  mean {100 * m['mean_distance_m']:5.2f} cm  "
          f"max {100 * m['max_distance_m']:5.2f} cm  speed {100 * m['mean_speed_along_path_m_per_s']:4.2f} cm/s  "
          f"prims {m['primitives_used']}", flush=True)
    return {**m, **files}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="frog-planner-eval", description=__doc__, epilog=EPILOG,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--library", type=Path, required=True, help="motion library (.npz)")
    ap.add_argument("--path", choices=["line", "sine", "ellipse", "all"], default="all")
    add_arguments(ap, PlannerSettings)
    ap.add_argument("--paper-cost", action="store_true",
                    help="the paper's exact planner: eq. 19 at the leaf, tangent heading, weights 500/50/300, "
                         "nearest-state transitions (overrides the weight, look-ahead and correction options)")
    ap.add_argument("--transitions", choices=["library", "simulator"], default="library",
                    help="predictions of the search: the library (paper) or exact ones from copies of the "
                         "running simulator (depth <= 2; about 9^depth simulated periods per decision)")
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
            args.settings = PlannerSettings.paper(period=args.settings.period, depth=args.settings.depth,
                                                  metric=args.settings.metric,
                                                  k_neighbours=args.settings.k_neighbours)
    except ValueError as exc:
        ap.error(str(exc))
    from frog_common.motion_library_file import LibraryFormatError
    paths = ["line", "sine", "ellipse"] if args.path == "all" or args.compare else [args.path]
    if args.compare and args.transitions == "simulator":
        runs = [(p, d, args.settings.metric) for d in (1, 2) for p in paths]
    elif args.compare:
        runs = [(p, d, m) for m in ("euclidean", "relative") for d in (1, 2, 3) for p in paths]
    else:
        runs = [(p, args.settings.depth, args.settings.metric) for p in paths]
    cache: dict = {}
    try:
        results = [_run(args, *r, cache) for r in runs]
    except (LibraryFormatError, ValueError, OSError) as exc:
        print(f"frog-planner-eval: error: {exc}", file=sys.stderr)
        return 2
    from frog_twin.core.evaluation import PATHS, path_min_radius
    for r in results:
        r["path_min_radius_m"] = path_min_radius(PATHS[{"sinusoid": "sine"}.get(r["path"], r["path"])]())
    if args.turning:
        from frog_twin.core.evaluation import turning_response
        print("\nturning response, each primitive repeated every period from rest for 45 s:")
        print(f"  {'prim':4s} {'steady COM circle cm':>20} {'speed cm/s':>10} {'yaw deg/s':>9} "
              f"{'63% yaw after s':>15} {'max side-slip deg':>17}")
        for prim in ("E", "G", "C"):
            tr = turning_response(prim, period=args.settings.period)
            print(f"  {prim:4s} {100 * tr.steady_radius:20.1f} {100 * tr.steady_speed:10.2f} "
                  f"{np.degrees(tr.steady_yaw_rate):9.1f} {tr.rise_time:15.1f} {np.degrees(tr.max_course_lag):17.0f}")
        for name in paths:
            print(f"  path {name:8s} smallest radius {100 * path_min_radius(PATHS[name]()):6.1f} cm")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "metrics.json").write_text(json.dumps(results, indent=1))
    if args.compare or len(results) > 1:
        print(f"\n{'path':8s} {'depth':>5} {'metric':>9} {'goal':>5} {'time s':>7} {'mean cm':>8} "
              f"{'max cm':>7} {'cm/s':>6}")
        for r in results:
            print(f"{r['path']:8s} {r['depth']:5d} {r['metric']:>9} {str(r['goal_reached']):>5} "
                  f"{(r['completion_time_s'] or float('nan')):7.1f} {100 * r['mean_distance_m']:8.2f} "
                  f"{100 * r['max_distance_m']:7.2f} {100 * r['mean_speed_along_path_m_per_s']:6.2f}")
    print(f"\nwrote {args.out / 'metrics.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
