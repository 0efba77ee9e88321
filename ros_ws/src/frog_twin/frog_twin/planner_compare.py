"""``frog-twin --planner-compare``: the paper's planner against this project's, with the library and
with the simulator in the loop, each run as the whole twin (vision, serial link).

Planners, on the same twin and library:

* ``paper``: eq. 19 at the leaf, weights 500/50/300, tangent heading, the relative metric;
* ``project``: this project's library planner at its defaults (the command line's settings);
* ``sim-d1`` / ``sim-d2``: the project's cost with ``transitions: simulator`` at depth 1 / 2
  (depth 2 with a beam of ``--compare-beam`` first primitives; 0 = all 81 sequences);
* ``sim-paper``: the paper's cost (as ``paper``) with ``transitions: simulator`` at depth 1, which
  separates the better predictions from the project's cost.

Paths: the paper's three, and each shared hardware run's reference path as waypoints from
its logged start pose with its fitted decision period (``--compare-runs DIR``). Output in the
run folder: ``compare.md`` (the table, the targets), ``compare.json`` and one PNG per path
with every planner's trajectory overlaid.
"""

from __future__ import annotations

import copy
import dataclasses
import json
import math
import re
from pathlib import Path

import numpy as np

from frog_common.atomic_files import atomic_write_text
from frog_planner.core.settings import PlannerSettings

PLANNERS = ("paper", "project", "sim-d1", "sim-d2", "sim-paper")
_FALLBACK = re.compile(r"decisions: (\d+) simulator, (\d+) library fallbacks")


def planner_settings(kind: str, base: PlannerSettings, period: float) -> tuple[PlannerSettings, str]:
    """(settings, transitions) of one compared planner at ``period``."""
    if kind in ("paper", "sim-paper"):
        return (PlannerSettings.paper(period=period, metric="relative"),
                "library" if kind == "paper" else "simulator")
    project = dataclasses.replace(base, period=period)
    if kind == "project":
        return project, "library"
    return dataclasses.replace(project, depth=1 if kind == "sim-d1" else 2), "simulator"


def _decision_counts(run_folder: Path) -> tuple[int, int]:
    """(simulator decisions, library fallbacks) from planner_node's closing log line (0, 0 without)."""
    log = run_folder / "planner_node.log"
    found = _FALLBACK.findall(log.read_text(errors="replace")) if log.is_file() else []
    return (int(found[-1][0]), int(found[-1][1])) if found else (0, 0)


def compare_table(results: list[dict]) -> str:
    """Markdown: mean distance per path and planner (mean over seeds), sums, and the targets."""
    paths = list(dict.fromkeys(r["path"] for r in results))
    kinds = [k for k in PLANNERS if any(r["planner"] == k for r in results)]
    cell = {}
    for k in kinds:
        for p in paths:
            runs = [r for r in results if r["planner"] == k and r["path"] == p]
            cell[k, p] = (float(np.mean([r["mean_distance_m"] for r in runs])) if runs else math.nan,
                          sum(r["finished"] for r in runs), len(runs),
                          sum(r["fallbacks"] for r in runs), sum(r["simulator_decisions"] for r in runs))
    head = "| path | floor cm | " + " | ".join(f"{k} cm" for k in kinds) + " |"
    lines = [head, "|" + "---|" * (len(kinds) + 2)]
    for p in paths:
        # each planner's own model predicts the frog's turns; the tightest gives the lowest floor
        floors = [r.get("floor_m", math.nan) for r in results if r["path"] == p]
        floor = min((f for f in floors if not math.isnan(f)), default=math.nan)
        row = [f"{cell[k, p][0] * 100:.2f} ({cell[k, p][1]}/{cell[k, p][2]})" for k in kinds]
        lines.append(f"| {p} | {floor * 100:.2f} | " + " | ".join(row) + " |")
    # a stopped comparison: sums and targets over the paths every planner has run as often
    done = [p for p in paths if cell[kinds[0], p][2] and len({cell[k, p][2] for k in kinds}) == 1]
    sums = {k: sum(cell[k, p][0] for p in done) for k in kinds}
    label = "sum" if len(done) == len(paths) else f"sum of the {len(done)} paths every planner has run"
    lines.append(f"| **{label}** | | " + " | ".join(f"**{sums[k] * 100:.2f}**" for k in kinds) + " |")
    lines.append("")
    lines.append("Cells: mean distance to the path over the seeds (runs that reached the goal / runs). Floor: "
                 "the best curvature-limited curve, with the tightest steady turns any compared planner's "
                 "model predicts.")
    sim = [k for k in kinds if k.startswith("sim")]
    if sim:
        lines.append("Simulator decisions / library fallbacks: " + "; ".join(
            f"{k} {sum(cell[k, p][4] for p in paths)} / {sum(cell[k, p][3] for p in paths)}" for k in sim) + ".")
        made = sum(cell[k, p][4] for k in sim for p in paths)
        missed = sum(cell[k, p][3] for k in sim for p in paths)
        if made + missed:
            share = made / (made + missed)
            lines.append(f"Decisions made within the period: {100 * share:.1f} % (target >= 99 %: "
                         f"{'met' if share >= 0.99 else 'NOT met'}).")
        if "project" in kinds:
            best_sim = min(sim, key=sums.get)
            worse = [p for p in done if cell[best_sim, p][0] > cell["project", p][0]]
            lines.append(f"Best simulator mode {best_sim} against the library mode (project): worse on "
                         f"{', '.join(_with_error(results, best_sim, 'project', p) for p in worse) or 'no path'} "
                         f"(target: none).")
    if "paper" in kinds:
        others = [k for k in kinds if k != "paper"]
        best = min(others, key=lambda k: sums[k]) if others else None
        if best is not None and done:      # nothing to compare before one path is done by all
            ratio = sums[best] / sums["paper"]
            worse = [p for p in done if cell[best, p][0] > cell["paper", p][0]]
            lines.append(f"Best mode {best}: sum {sums[best] * 100:.2f} cm = {ratio:.2f} x the paper planner's "
                         f"{sums['paper'] * 100:.2f} cm (target <= 0.70: {'met' if ratio <= 0.7 else 'NOT met'}); "
                         f"paths worse than the paper planner: "
                         f"{', '.join(_with_error(results, best, 'paper', p) for p in worse) or 'none'}.")
    if any(len(_means(results, k, p)) > 1 for k in kinds for p in paths):
        lines.append("Worse by: the difference of the seed means, +- its standard error from the spread of the "
                     "seeds (sqrt(s1^2/n1 + s2^2/n2)); a difference within about 2 standard errors is within "
                     "the seeds' noise.")
    return "\n".join(lines)


def _means(results, kind: str, path: str) -> list[float]:
    return [r["mean_distance_m"] for r in results if r["planner"] == kind and r["path"] == path]


def _with_error(results, kind: str, other: str, path: str) -> str:
    """'sine (+0.11 +- 0.42 cm)': how much worse ``kind`` is than ``other`` on ``path``, and the
    standard error of that difference from the seeds' spread (none with one seed each)."""
    a, b = np.array(_means(results, kind, path)), np.array(_means(results, other, path))
    diff = (a.mean() - b.mean()) * 100
    if len(a) < 2 or len(b) < 2:
        return f"{path} (+{diff:.2f} cm)"
    se = math.sqrt(a.var(ddof=1) / len(a) + b.var(ddof=1) / len(b)) * 100
    return f"{path} (+{diff:.2f} +- {se:.2f} cm)"


def plot_path(path_name: str, path_points, tracks: list[tuple[str, np.ndarray]], file: Path) -> None:
    """Every planner's trajectory (x, y) over the path."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7, 5.5))
    ax.plot(path_points[:, 0] * 100, path_points[:, 1] * 100, "k--", lw=1.5, label="path")
    colours = dict(zip(PLANNERS, ("tab:red", "tab:blue", "tab:green", "tab:purple", "tab:orange")))
    seen = set()
    for label, xy in tracks:
        kind = label.split(" ")[0]
        ax.plot(xy[:, 0] * 100, xy[:, 1] * 100, color=colours.get(kind, "grey"), lw=1.2, alpha=0.8,
                label=kind if kind not in seen else None)
        seen.add(kind)
    ax.set_aspect("equal")
    ax.set_xlabel("x [cm]")
    ax.set_ylabel("y [cm]")
    ax.set_title(f"{path_name}: planners compared (twin, vision + serial link)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(file, dpi=120)
    plt.close(fig)


def _cases(args) -> list:
    """Every compared path (:mod:`frog_twin.core.cases`): the paper's, then the hardware runs'."""
    from frog_twin.core.cases import PATH_NAMES, hardware_cases, paper_cases
    names = (PATH_NAMES if args.compare_paths in (None, "all") else
             () if args.compare_paths == "none" else args.compare_paths.split(","))
    cases = paper_cases(args.path_settings, args.settings.period, names)
    if args.compare_runs is not None:
        cases += hardware_cases(args.compare_runs, args.out_folder / "paths", args.path_settings)
    return cases


def run_config(args, kind: str, settings: PlannerSettings, transitions: str, path_settings, start, duration,
               node_params) -> dict:
    """What decides one compared run's outcome besides its seed: a resumed comparison reuses a run
    only if this is the same (as JSON)."""
    return json.loads(json.dumps({
        "planner": kind, "settings": settings.as_dict(), "transitions": transitions,
        "node_params": node_params, "library": str(Path(args.library).resolve()),
        "real_time_factor": args.real_time_factor,
        "vision": not args.no_vision, "serial": not args.direct, "duration_s": duration,
        "path": path_settings.as_dict(), "start_pose": None if start is None else list(start),
        "twin": {k: getattr(args, k) for k in ("limb_strength_sd", "kick_strength_sd", "yaw_disturbance_sd",
                                                "yaw_disturbance_tau")}}, default=str))


class ResumeMismatch(ValueError):
    """A run in the output folder was made with other settings than this command's."""


def _earlier_result(file: Path, config: dict) -> dict | None:
    """The run's result from an earlier (interrupted) comparison in the same folder, or None to run it."""
    if not file.is_file():
        return None
    try:
        result = json.loads(file.read_text())
    except ValueError:            # written whole by a rename, so only a damaged disk gets here: run it again
        return None
    if result.get("config") != config:
        diff = sorted(k for k in set(config) | set(result.get("config") or {})
                      if (result.get("config") or {}).get(k) != config.get(k))
        raise ResumeMismatch(f"{file} was run with other settings ({', '.join(diff)}) than this command's: "
                             f"resume with the same options, or use another --out")
    return result


def _plan(args, out: Path) -> list[dict]:
    """Every compared run, in order (path by path, then planner, then seed), with its settings."""
    kinds = [k.strip() for k in args.compare_planners.split(",")]
    seeds = list(range(args.seed, args.seed + args.seeds))
    plan = []
    for case in _cases(args):
        duration = args.duration if case.duration is None else (args.duration or case.duration)
        for kind in kinds:
            settings, transitions = planner_settings(kind, args.settings, case.period)
            for seed in seeds:
                a = copy.copy(args)
                a.seed, a.transitions = seed, transitions
                if kind == "sim-d2":       # beam: the 9 + 81 rollouts of a full tree miss the deadline here
                    a.node_params = copy.deepcopy(args.node_params)
                    a.node_params.setdefault("planner_node", {})["beam_width"] = args.compare_beam
                label = f"{case.name}_{kind}_s{seed}"
                plan.append({"case": case, "kind": kind, "seed": seed, "args": a, "settings": settings,
                             "transitions": transitions, "duration": duration, "label": label,
                             "folder": out / case.name / label,
                             "config": run_config(a, kind, settings, transitions, case.path_settings,
                                                  case.start_pose, duration, a.node_params)})
    return plan


def main_compare(args, root: Path) -> int:
    """Every planner x path x seed as one twin run; the table and the figures.

    Each run's result is kept whole in ``<out>/<path>/<label>/compare_result.json``, so the same
    command with the same ``--out`` resumes an interrupted comparison (Ctrl-C, SIGTERM) and runs
    only what is missing; a kept run made with other settings stops the command
    (:class:`ResumeMismatch`) before anything runs.
    """
    import time

    from frog_twin import twin
    out = args.out or root / "runs" / time.strftime("compare_%Y%m%d_%H%M%S")
    out.mkdir(parents=True, exist_ok=True)
    args.out_folder = out
    plan = _plan(args, out)
    earlier = [_earlier_result(r["folder"] / RESULT_FILE, r["config"]) for r in plan]
    if any(earlier):
        print(f"planner comparison: {sum(map(bool, earlier))} of {len(plan)} runs done earlier in {out}", flush=True)
    results = []
    try:
        for i, (run, result) in enumerate(zip(plan, earlier), 1):
            settings, label = run["settings"], run["label"]
            if result is None:
                print(f"[{i}/{len(plan)}] {label}: depth {settings.depth}, transitions {run['transitions']}, "
                      f"period {settings.period:.3f} s", flush=True)
                case = run["case"]
                rec, m = twin.run_twin(run["args"], label, run["folder"], case.path_settings, case.start_pose,
                                       settings, run["duration"])
                result = _result(run, rec, m)
                atomic_write_text(run["folder"] / RESULT_FILE, json.dumps(result, indent=1, default=float) + "\n")
                print(f"  mean {m['mean_distance_m'] * 100:.2f} cm, goal {'yes' if m['goal_reached'] else 'no'}"
                      + (f", {result['simulator_decisions']} simulator decisions, {result['fallbacks']} fallbacks"
                         if run["transitions"] == "simulator" else "")
                      + f", wall {m['wall_time_s']:.0f} s", flush=True)
            results.append(result)
            if i == len(plan) or plan[i]["case"].name != run["case"].name:      # the path's last run
                _plot_case(run["case"].name, [r for r in results if r["path"] == run["case"].name],
                           out / f"{run['case'].name}_compare.png")
    finally:      # also when stopped (Ctrl-C, SIGTERM): the table of what is done, and how to go on
        _write_summary(args, out, results, len(plan))
    return 0


RESULT_FILE = "compare_result.json"


def _plot_case(name: str, results: list[dict], file: Path) -> None:
    points = next((r["path_points"] for r in results if r["path_points"]), None)
    if points is not None:
        plot_path(name, np.asarray(points, dtype=float),
                  [(f"{r['planner']} s{r['seed']}", np.asarray(r["track"], dtype=float).reshape(-1, 2))
                   for r in results], file)


def _write_summary(args, out: Path, results: list[dict], planned: int) -> None:
    """compare.json (without the tracks), compare.md and the table on stdout."""
    brief = [{k: v for k, v in r.items() if k not in ("track", "path_points", "config")} for r in results]
    (out / "compare.json").write_text(json.dumps(brief, indent=1, default=float) + "\n")
    table = compare_table(results) if results else "(no run done)"
    seeds = list(range(args.seed, args.seed + args.seeds))
    partial = (f"{len(results)} of {planned} runs done: the same command with --out {out} runs the rest"
               if len(results) < planned else "")
    head = (f"# Planner comparison (twin with vision and the serial link; library {args.library}; "
            f"real-time factor {args.real_time_factor:g}; seeds {seeds}; sim-d2 beam {args.compare_beam})\n\n"
            + (partial + "\n\n" if partial else ""))
    (out / "compare.md").write_text(head + table + "\n")
    print()
    if partial:
        print(partial)
    print(table)
    print(f"\ntable, per-path figures, runs: {out}", flush=True)


def _result(run: dict, rec, m: dict) -> dict:
    """One compared run: its numbers, its settings, its true track and the path (for the figure when resumed)."""
    sim_n, fallbacks = _decision_counts(run["folder"])
    truth = rec.truth[rec.truth[:, 0] >= m["start_time_s"] - 1e-9]
    return {"path": run["case"].name, "planner": run["kind"], "seed": run["seed"], "depth": run["settings"].depth,
            "transitions": run["transitions"], "config": run["config"], "mean_distance_m": m["mean_distance_m"],
            "max_distance_m": m["max_distance_m"], "finished": bool(m["goal_reached"]),
            "completion_time_s": m["completion_time_s"], "simulator_decisions": sim_n,
            "fallbacks": fallbacks, "wall_time_s": m["wall_time_s"],
            "floor_m": (m.get("feasibility") or {}).get("floor_mean_distance_m", math.nan),
            "primitives": m["primitives_used"], "plot": m["plot"],
            "track": np.round(truth[:, 1:3], 6).tolist(),
            "path_points": None if rec.path is None else np.round(np.asarray(rec.path)[:, :2], 6).tolist()}
