"""``frog-twin --fault-campaign``: every fault at several moments of a path, several seeds, one table.

Each run is one :func:`frog_twin.twin.run_twin` with one fault (``--fault-classes``: one
run per fault class, several faults in it: the reduced form the system tests run). The
summary has per fault: runs completed / stopped with a reason / failed, the limb pulses and
those on a state older than the bound, by the recording's audit (must be 0), the oldest state
any pulse rested on, messages the recorder lost while it was up (must be 0), and the time to
recover (simulated s from the fault's end until the planner follows again).
"""

from __future__ import annotations

import copy
import json
import statistics
import time
import traceback
from pathlib import Path

from frog_common.atomic_files import atomic_write_text
from frog_twin.core.faults import CAMPAIGN_FAULTS, CAMPAIGN_MOMENTS, FAULT_CLASSES, campaign_plan, parse_faults

#: the paths' nominal times [s simulated] on the twin (the main job), for the moments
NOMINAL_TIME_S = {"line": 15.7, "sine": 14.3, "ellipse": 24.3}


def _runs(args):
    """[(label, path, seed, [Fault])] of this campaign."""
    paths = [p.strip() for p in args.campaign_paths.split(",") if p.strip()]
    seeds = [args.seed + i for i in range(args.seeds)]
    if args.fault_classes:
        return [(f"{cls}_{path}_s{seed}", path, seed, parse_faults(spec))
                for cls, spec in FAULT_CLASSES.items() for path in paths for seed in seeds]
    faults = CAMPAIGN_FAULTS if args.campaign_faults is None else \
        [s.strip() for s in args.campaign_faults.split(";") if s.strip()]
    moments = {1: CAMPAIGN_MOMENTS[1:2], 2: CAMPAIGN_MOMENTS[::2], 3: CAMPAIGN_MOMENTS}[args.moments]
    plan = campaign_plan(faults, moments, seeds, paths, NOMINAL_TIME_S)
    return [(f"{f.label().replace(':', '-').replace('@', '_at').replace(',', '_').replace('=', '')}_{path}_s{seed}",
             path, seed, [f]) for path, seed, f in plan]


def _shard(runs, shard: str | None):
    """The runs of shard 'K/N' (every N-th from the K-th), all runs without one."""
    if shard is None:
        return runs
    k, n = (int(v) for v in shard.split("/"))
    return runs[k - 1::n]


def _result_file(out: Path, label: str) -> Path:
    return out / label / "result.json"


def _gathered(out: Path, runs):
    """The results of the campaign's runs done so far in ``out`` (by this process or another shard)."""
    done = []
    for label, *_ in runs:
        f = _result_file(out, label)
        if f.is_file():
            try:
                done.append(json.loads(f.read_text()))
            except ValueError:        # a shard writing it just now; it is read at that shard's end
                pass
    return done


def main_campaign(args, root: Path) -> int:
    from frog_twin.twin import run_path
    planned = _runs(args)
    runs = _shard(planned, args.campaign_shard)
    out = args.out or root / "runs" / time.strftime("faults_%Y%m%d_%H%M%S")
    out.mkdir(parents=True, exist_ok=True)
    todo = [r for r in runs if not _result_file(out, r[0]).is_file()]
    print(f"fault campaign: {len(runs)} runs" + (f" (shard {args.campaign_shard} of {len(planned)})"
                                                  if args.campaign_shard else "")
          + (f", {len(runs) - len(todo)} already done in it" if len(todo) < len(runs) else "")
          + f" -> {out}", flush=True)
    try:
        for i, (label, path, seed, faults) in enumerate(todo, 1):
            print(f"[{i}/{len(todo)}] {label}: {'; '.join(f.label() for f in faults)}", flush=True)
            _run_one(args, run_path, out, label, path, seed, faults)
    finally:       # also when stopped (Ctrl-C, SIGTERM): the table of what is done, and how to go on
        results = _gathered(out, planned)
        (out / "campaign.json").write_text(json.dumps(results, indent=1, default=float) + "\n")
        table = summary_table(results)
        head = f"{len(results)} of {len(planned)} runs of the campaign done"
        (out / "campaign.md").write_text(head + "\n\n" + table + "\n")
        print()
        print(head + ("" if len(results) == len(planned) else
                      f" (the same command with --out {out} resumes it)"))
        print(table)
        print(f"\nper-run details: {out / 'campaign.json'}", flush=True)
    bad = [r for r in results if r["outcome"] == "failed"]
    return 1 if bad else 0


def _run_one(args, run_path, out: Path, label: str, path: str, seed: int, faults) -> None:
    """One run of the campaign; its result is written whole to ``<out>/<label>/result.json``."""
    a = copy.copy(args)
    a.seed = seed
    started = time.monotonic()
    try:
        m = run_path(a, path, out / label / path, faults=faults)
        rep = m["faults"]
    except Exception as exc:      # a run that breaks is a finding of the campaign, not its end
        rep = {"outcome": "failed", "stop_reason": f"{type(exc).__name__}: {exc}",
               "traceback": traceback.format_exc(), "stale_pulses": [], "recorder_lost": 0,
               "per_fault": [{"fault": f.label(), "recovery_s": None} for f in faults]}
    rep.update(label=label, path=path, seed=seed, wall_s=round(time.monotonic() - started, 1))
    print(f"    -> {rep['outcome']}" + (f" ({rep['stop_reason']})" if rep.get("stop_reason") else "")
          + f"; pulses on stale state {len(rep['stale_pulses'])}, recorder lost {rep['recorder_lost']}", flush=True)
    # written whole (a rename): an interrupted campaign resumes from these files (same --out)
    atomic_write_text(_result_file(out, label), json.dumps(rep, indent=1, default=float) + "\n")


def _kind(fault_label: str) -> str:
    """'kill:tracker_node@3' -> 'kill:tracker_node'; 'kill:tracker_node@3,restart=no' keeps ',restart=no'."""
    head, _, rest = fault_label.partition("@")
    return head + (",restart=no" if "restart=no" in rest else "")


def summary_table(results) -> str:
    """Markdown: one row per fault kind over its runs (a class run counts for each of its faults)."""
    rows = {}
    for r in results:
        for pf in r["per_fault"]:
            row = rows.setdefault(_kind(pf["fault"]), {"runs": 0, "completed": 0, "stopped": 0, "failed": 0,
                                                       "stale": 0, "pulses": 0, "oldest": 0.0, "lost": 0,
                                                       "recovery": [], "never": 0})
            row["runs"] += 1
            row[r["outcome"]] += 1
            row["stale"] += len(r["stale_pulses"])
            ages = r.get("pulse_ages") or {}
            row["pulses"] += ages.get("pulses", 0)
            row["oldest"] = max(row["oldest"], (ages.get("published") or {}).get("max", 0.0))
            row["lost"] += r["recorder_lost"]
            if pf.get("recovery_s") is None:
                row["never"] += 1
            else:
                row["recovery"].append(pf["recovery_s"])
    lines = ["| fault | runs | completed | stopped with a reason | failed | pulses | pulses on stale state "
             "| oldest state at a pulse [s] | recorder lost | recovery median / max [s] | not recovered |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for kind, row in rows.items():
        rec = row["recovery"]
        rec_text = f"{statistics.median(rec):.1f} / {max(rec):.1f}" if rec else "-"
        never = row["never"]
        if kind == "emergency":      # latched until a person clears it: the run stops, by design
            rec_text, never = "by a person", "-"
        lines.append(f"| {kind} | {row['runs']} | {row['completed']} | {row['stopped']} | {row['failed']} | "
                     f"{row['pulses']} | {row['stale']} | {row['oldest']:.3f} | {row['lost']} | {rec_text} | "
                     f"{never} |")
    return "\n".join(lines)
