"""``frog-twin --planner-compare``: the paper's planner against this project's, with the library and
with the simulator in the loop (issue 19.3), each run as the whole twin (vision, serial link).

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
    sums = {k: sum(cell[k, p][0] for p in paths) for k in kinds}
    lines.append("| **sum** | | " + " | ".join(f"**{sums[k] * 100:.2f}**" for k in kinds) + " |")
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
            best_sim = min(sim, key=lambda k: sum(cell[k, p][0] for p in paths))
            worse = [p for p in paths if cell[best_sim, p][0] > cell["project", p][0]]
            lines.append(f"Best simulator mode {best_sim} against the library mode (project): worse on "
                         f"{', '.join(worse) if worse else 'no path'} (target: none).")
    if "paper" in kinds:
        others = [k for k in kinds if k != "paper"]
        best = min(others, key=lambda k: sums[k]) if others else None
        if best is not None:
            ratio = sums[best] / sums["paper"]
            worse = [p for p in paths if cell[best, p][0] > cell["paper", p][0]]
            lines.append(f"Best mode {best}: sum {sums[best] * 100:.2f} cm = {ratio:.2f} x the paper planner's "
                         f"{sums['paper'] * 100:.2f} cm (target <= 0.70: {'met' if ratio <= 0.7 else 'NOT met'}); "
                         f"paths worse than the paper planner: {', '.join(worse) if worse else 'none'}.")
    return "\n".join(lines)


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


def main_compare(args, root: Path) -> int:
    import time

    from frog_twin.twin import run_twin
    out = args.out or root / "runs" / time.strftime("compare_%Y%m%d_%H%M%S")
    out.mkdir(parents=True, exist_ok=True)
    args.out_folder = out
    kinds = [k.strip() for k in args.compare_planners.split(",")]
    cases = _cases(args)
    seeds = list(range(args.seed, args.seed + args.seeds))
    total, done = len(cases) * len(kinds) * len(seeds), 0
    results = []
    for case in cases:
        name, path_settings, start, period = case.name, case.path_settings, case.start_pose, case.period
        tracks, points = [], None
        for kind in kinds:
            settings, transitions = planner_settings(kind, args.settings, period)
            for seed in seeds:
                done += 1
                a = copy.copy(args)
                a.seed, a.transitions = seed, transitions
                if kind == "sim-d2":           # beam: the 9 + 81 rollouts of a full tree miss the deadline here
                    a.node_params = copy.deepcopy(args.node_params)
                    a.node_params.setdefault("planner_node", {})["beam_width"] = args.compare_beam
                label = f"{name}_{kind}_s{seed}"
                print(f"[{done}/{total}] {label}: depth {settings.depth}, transitions {transitions}, "
                      f"period {period:.3f} s", flush=True)
                duration = args.duration if case.duration is None else (args.duration or case.duration)
                rec, m = run_twin(a, label, out / name / label, path_settings, start, settings, duration)
                sim_n, fallbacks = _decision_counts(out / name / label)
                t0 = m["start_time_s"]
                truth = rec.truth[rec.truth[:, 0] >= t0 - 1e-9]
                tracks.append((f"{kind} s{seed}", truth[:, 1:3]))
                points = rec.path if rec.path is not None else points
                results.append({"path": name, "planner": kind, "seed": seed, "depth": settings.depth,
                                "transitions": transitions, "mean_distance_m": m["mean_distance_m"],
                                "max_distance_m": m["max_distance_m"], "finished": bool(m["goal_reached"]),
                                "completion_time_s": m["completion_time_s"], "simulator_decisions": sim_n,
                                "fallbacks": fallbacks, "wall_time_s": m["wall_time_s"],
                                "floor_m": (m.get("feasibility") or {}).get("floor_mean_distance_m", math.nan),
                                "primitives": m["primitives_used"], "plot": m["plot"]})
                print(f"  mean {m['mean_distance_m'] * 100:.2f} cm, goal {'yes' if m['goal_reached'] else 'no'}"
                      + (f", {sim_n} simulator decisions, {fallbacks} fallbacks" if transitions == "simulator" else "")
                      + f", wall {m['wall_time_s']:.0f} s", flush=True)
                (out / "compare.json").write_text(json.dumps(results, indent=1, default=float) + "\n")
        if points is not None:
            plot_path(name, np.asarray(points), tracks, out / f"{name}_compare.png")
    table = compare_table(results)
    head = (f"# Planner comparison (twin with vision and the serial link; library {args.library}; "
            f"real-time factor {args.real_time_factor:g}; seeds {seeds}; sim-d2 beam {args.compare_beam})\n\n")
    (out / "compare.md").write_text(head + table + "\n")
    print()
    print(table)
    print(f"\ntable, per-path figures, runs: {out}")
    return 0
