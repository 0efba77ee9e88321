"""``frog-twin --replay RUN.csv`` / ``--replay-all DIR``: the real robot's experiments re-run in the twin.

The setup (waypoints, start pose, decision period, real trajectory) comes from
:mod:`frog_twin.core.replay`; each replay is one :func:`frog_twin.twin.run_twin` (the whole
chain of the main job, or simulator-only with ``--no-vision --direct``); the real run and
the twin's ground truth are scored by the same :func:`~frog_twin.core.replay.replay_metrics`.

Per run it writes into ``<out>/<run>/``: ``<run>_replay.png`` (real and twin trajectories on
the path, signed lateral offset over time), ``<run>_replay.{txt,csv,json}`` (the table real
vs twin and every number), and per seed the twin's own outputs (``<run>[_s<seed>].png``,
``.mp4`` with vision, ``.json``, the MCAP recording and the node logs). ``--replay-all``
adds ``summary.{txt,csv,json}`` with the pooled row.
"""

from __future__ import annotations

import copy
import csv
import dataclasses
import json
import math
import time
from pathlib import Path

import numpy as np

from frog_planner.core.settings import PathSettings, PlannerSettings, from_arguments

from frog_sim.core.hardware_runs import DECISION_TO_FIRING_S
from frog_twin.core import replay
from frog_common.state_age import MAX_STATE_AGE_S

# simulated time allowed per replay when --duration is not given
from frog_twin.core.cases import REPLAY_DURATION_FACTOR, REPLAY_EXTRA_S

#: The authors' planner loop (their published control code, softmachineslab/frog control_code/src):
#: it decided on the mean of the 9 tracker states it polled since its last decision, about
#: 9 x 0.07 s of frames (its share of the tracking loop, as the logger's), and an executor sent
#: the newest decision once a period.
PAPER_REPLAN_INTERVAL_S = 0.63


def paper_loop_params(args) -> dict:
    """Node parameters of the robot's own loop for ``--paper-cost`` (unless ``--ideal-loop``): the
    planner's asynchronous decisions on mean states, its library search as coded (axes and yaw
    units of the authors' library, ``TransitionModel`` lookup), and the authors' tracker, which
    gave the raw pose and frame-to-frame velocity differences (with vision). Their loop fired on
    states up to a replan interval older than the project's loop does, so its replay raises the
    state-age bound of the planner and the bridge by that interval (only here: a replay of their
    system, not a setting to run a robot with)."""
    if not args.paper_cost or getattr(args, "ideal_loop", False):
        return {}
    bound = PAPER_REPLAN_INTERVAL_S + MAX_STATE_AGE_S
    params = {"planner_node": {"replan_interval": PAPER_REPLAN_INTERVAL_S, "lookup": "authors_code",
                               "max_state_age_s": bound}}
    if not args.direct:
        params["bridge_node"] = {"max_state_age_s": bound}
    if not args.no_vision:
        params["tracker_node"] = {"estimator": "frame_difference"}
    return params


def direct_loop_params(args) -> dict:
    """Node parameters of a replay without the serial link (``--direct``): sim_node fires each
    primitive the robot's decision-to-firing delay after its stamp, in simulated time (the relay,
    BLE and firmware the emulator would stand for), so the firing times do not follow the
    wall-clock latencies of the processes."""
    return {"sim_node": {"command_delay_s": DECISION_TO_FIRING_S}} if args.direct else {}


def finish_line(args) -> float:
    """Half-width of the replay's finish line [m]: the user's ``--goal-lateral-tolerance`` or
    :data:`~frog_twin.core.replay.FINISH_LINE_HALF_WIDTH_M`."""
    return args.path_settings.goal_lateral_tolerance or replay.FINISH_LINE_HALF_WIDTH_M


def _merged(first: dict, then: dict) -> dict:
    out = {node: dict(values) for node, values in first.items()}
    for node, values in then.items():
        out.setdefault(node, {}).update(values)
    return out


def replay_planner_settings(args, period: float) -> PlannerSettings:
    """The planner of a replay at the run's ``period``: the paper's (``--paper-cost``: eq. 19 at the
    leaf with weights 500/50/300, depth 1, tangent heading, relative metric, nearest-state transitions; see
    :meth:`PlannerSettings.paper`) or the project's settings from the command line."""
    if args.paper_cost:
        return PlannerSettings.paper(period=period, metric="relative", k_neighbours=args.settings.k_neighbours)
    return dataclasses.replace(args.settings, period=period)


def _write_rows(rows: list[dict], file: Path) -> None:
    with open(file, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        for r in rows:
            w.writerow({k: ("" if v is None else v) for k, v in r.items()})


def replay_run(args, run_csv: Path, path_csv: Path | None, out: Path, progress: str = "") -> dict:
    """Replay one hardware run for every seed; write its plot and table; return all numbers."""
    from frog_twin.twin import run_twin
    setup = replay.replay_setup(run_csv, path_csv, None if args.tag_offset_deg is None
                                else math.radians(args.tag_offset_deg))
    tol = args.path_settings.goal_tolerance
    band = finish_line(args)
    real = replay.real_metrics(setup, goal_tolerance=tol, finish_line=band)
    settings = replay_planner_settings(args, setup.period)
    folder = out / setup.name
    folder.mkdir(parents=True, exist_ok=True)
    waypoints = replay.write_waypoints(setup.path, folder / f"{setup.name}_waypoints.csv")
    # the twin's planner stops at the finish line as the robot's experiment did (and as it is scored)
    path_settings = dataclasses.replace(args.path_settings, path_type="waypoints", waypoint_file=str(waypoints),
                                        goal_lateral_tolerance=band)
    duration = args.duration or REPLAY_DURATION_FACTOR * float(setup.time[-1]) + REPLAY_EXTRA_S
    x0, y0, h0 = setup.start_pose
    print(f"replay {progress}{setup.name}: period {setup.period:.4f} s, start ({x0:.3f}, {y0:.3f}) m "
          f"{math.degrees(h0):.1f} deg, tag offset {math.degrees(setup.tag_offset):+.1f} deg "
          f"({setup.tag_offset_source}), twin's tag {'aligned' if args.aligned_tag else 'turned as mounted'}; "
          f"planner {'paper' if args.paper_cost else 'project'}"
          f"{' in the robot' + chr(39) + 's loop' if paper_loop_params(args) else ''}; "
          f"at most {duration:.0f} s simulated", flush=True)
    twins, tracks = [], []
    # the robot's planner saw the tag's heading, body heading - offset: the twin's tag is mounted
    # so (camera_sim tag_yaw, or the vision-free alias), and its tracker calibrates no offset either
    tag_yaw = 0.0 if args.aligned_tag else -setup.tag_offset
    for seed in args.seed_list:
        a = copy.copy(args)
        a.seed = seed
        a.tag_yaw = tag_yaw
        a.node_params = _merged(_merged(paper_loop_params(args), direct_loop_params(args)),
                                getattr(args, "node_params", {}))   # --node-param last
        label = setup.name if len(args.seed_list) == 1 else f"{setup.name}_s{seed}"
        rec, tm = run_twin(a, label, folder / label, path_settings, setup.start_pose, settings, duration)
        # the run's own window: from the first decision to its end (what the recorder caught while
        # the nodes stopped is not the run's, as in the twin's report)
        t0 = tm["start_time_s"]
        t1 = math.inf if tm["end_time_s"] is None else tm["end_time_s"]
        truth = rec.truth[(rec.truth[:, 0] >= t0 - 1e-9) & (rec.truth[:, 0] <= t1 + 1e-9)]
        decided = [(t - t0, n) for t, n in rec.primitives if t0 - 1e-9 <= t < t1 - 1e-9]
        m = replay.replay_metrics(truth[:, 0] - t0, truth[:, 1:3], setup.path, [d for d, _ in decided],
                                  [n for _, n in decided], goal_tolerance=tol, finish_line=band)
        m.update(seed=seed, planner_goal_time_s=tm["completion_time_s"], wall_time_s=tm["wall_time_s"],
                 twin_plot=tm["plot"], video=tm["video"], recording=tm["recording"])
        twins.append(m)
        tracks.append((f"twin seed {seed}", np.c_[truth[:, 0] - t0, truth[:, 1:3]]))
        print(f"  {label}: mean {100 * m['mean_distance_m']:.2f} cm (real {100 * real['mean_distance_m']:.2f}), "
              f"lateral {100 * m['mean_signed_lateral_m']:+.2f} cm (real {100 * real['mean_signed_lateral_m']:+.2f}), "
              f"finished {'yes' if m['finished'] else 'no'}, wall {tm['wall_time_s']:.0f} s", flush=True)
    png = folder / f"{setup.name}_replay.png"
    replay.plot_replay(setup, tracks, real, twins, png)
    rows = replay.comparison_rows(setup.name, real, twins)
    text = replay.format_rows(rows)
    (folder / f"{setup.name}_replay.txt").write_text(text + "\n")
    _write_rows(rows, folder / f"{setup.name}_replay.csv")
    result = {"run": setup.name, "setup": setup.summary(), "planner": dataclasses.asdict(settings),
              "planner_kind": "paper" if args.paper_cost else "project",
              "robot_loop_params": _merged(paper_loop_params(args), direct_loop_params(args)),
              "real": real, "twins": twins, "spread": {
                  name: replay.seed_spread([t[key] for t in twins], real[key])
                  for name, key in (("mean_distance_m", "mean_distance_m"),
                                    ("mean_signed_lateral_m", "mean_signed_lateral_m"),
                                    ("mean_speed_along_path_m_per_s", "mean_speed_along_path_m_per_s"))},
              "rows": rows, "plot": str(png),
              "settings": {"vision": not args.no_vision, "serial": not args.direct, "seeds": args.seed_list,
                           "real_time_factor": args.real_time_factor, "limb_strength_sd": args.limb_strength_sd,
                           "kick_strength_sd": args.kick_strength_sd, "tag_yaw_rad": tag_yaw,
                           "yaw_disturbance_sd": args.yaw_disturbance_sd,
                           "yaw_disturbance_tau_s": args.yaw_disturbance_tau,
                           "duration_s": duration, "library": str(args.library), "finish_line_m": band,
                           "goal_tolerance_m": tol},
              "units": {"distance": "m (rows: cm)", "time": "s from the first decision", "speed": "m/s"}}
    (folder / f"{setup.name}_replay.json").write_text(json.dumps(result, indent=1, default=float) + "\n")
    return result


def main_replay(args, root: Path) -> int:
    """``--replay`` / ``--replay-all`` (arguments already parsed and checked by ``frog-twin``)."""
    args.seed_list = [args.seed + i for i in range(args.seeds)]
    args.path_settings = from_arguments(PathSettings, args, path_type="line")
    kind = "paper" if args.paper_cost else "project"
    out = args.out or root / "runs" / time.strftime(f"replay_{kind}_%Y%m%d_%H%M%S")
    out.mkdir(parents=True, exist_ok=True)
    if args.replay is not None:
        res = replay_run(args, args.replay, args.path, out)
        print()
        print(replay.format_rows(res["rows"]))
        print(f"\nplots, tables, JSON: {out / res['run']}")
        return 0
    runs = replay.find_runs(args.replay_all)
    if not runs:
        raise FileNotFoundError(f"{args.replay_all}: no <run>.csv with a matching <run>_path.csv")
    results = []
    for i, (run_csv, path_csv) in enumerate(runs):
        results.append(replay_run(args, run_csv, path_csv, out, progress=f"[{i + 1}/{len(runs)}] "))
    rows = replay.summary_rows(results)
    groups = replay.pooled_groups(results)
    pool = groups["all"]
    text = replay.format_summary(rows, pool, groups)
    detail = "\n".join(replay.format_rows(r["rows"]) for r in results)
    (out / "summary.txt").write_text(f"planner: {kind}\n{text}\n\nper run and seed:\n{detail}\n")
    _write_rows(rows + [replay.pooled_row(rows, p, f"pooled {label}") for label, p in groups.items()],
                out / "summary.csv")
    (out / "summary.json").write_text(json.dumps({"planner": kind, "rows": rows, "pooled": pool, "groups": groups,
                                                  "runs": results}, indent=1, default=float) + "\n")
    print(f"\nplanner: {kind}")
    print(text)
    print(f"\nper-run plots and tables: {out}/<run>/; summary: {out / 'summary.txt'} (.csv, .json)")
    return 0
