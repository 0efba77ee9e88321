"""Before/after: the headline figures of several benches on two revisions, measured in one run.

A refactor should change no figure beyond noise. This script checks out ``--base`` (a git
revision) into a temporary worktree beside this checkout (sharing its .venv, building its
own workspace), then runs each bench in both trees, alternating base and this tree within
each repeat so that both see the same machine load, and prints per figure the median of
each side and the ratio this / base. Each figure is the number a regular expression finds
in the bench's output (its own medians, wall and CPU where the bench prints both).

    ./dev run python bench/revisions.py --base 6cb0d55                     # all figures, 3 repeats
    ./dev run python bench/revisions.py --base HEAD~5 --only planner --repeats 5
    ./dev run python bench/revisions.py --base 6cb0d55 --keep /tmp/base    # reuse that worktree

The figures (name, bench command, regex) are in :data:`FIGURES`. Exit 0 after printing;
1 if a bench failed or printed no figure.
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# name, bench script and arguments, {figure: regex with one number group}
FIGURES = [
    ("planner", ["bench/planner_latency.py", "--decisions", "300", "--loop-decisions", "20", "3"], {
        "planner depth 1 decide, median [ms]": r"^\s+1\s+9\s+([\d.]+) ms",
        "planner depth 3 decide, median [ms]": r"^\s+3\s+729\s+([\d.]+) ms",
    }),
    ("softkin", ["bench/softkin_benchmarks.py", "iteration", "--reps", "10"], {
        "softkin FK iteration, wall [s]": r"^iteration\s+ours\s+([\d.]+) s",
        "softkin FK iteration, CPU [s]": r"^iteration\s+ours\s+[\d.]+ s \| cpu\s+([\d.]+) s",
    }),
    ("frog_sim", ["bench/frog_sim_realtime.py", "--sim-seconds", "3", "--repeats", "3", "--numpy-seconds", "0.2",
                  "--numpy-repeats", "1"], {
        "frog_sim real-time factor, CPU [x]": r"Newton\): median real-time factor ([\d.]+)x by CPU",
        "frog_sim real-time factor, wall [x]": r"Newton\): median real-time factor [\d.]+x by CPU time, ([\d.]+)x",
    }),
    ("vision", ["bench/vision_tracker.py", "--frames", "150"], {
        "tracker per frame, wall median [ms]": r"^target median <= 10 ms: \w+ \w*\s*\(([\d.]+) ms\)",
    }),
    ("bridge", ["bench/bridge_latency.py", "--samples", "100", "--rate", "10"], {
        "bridge primitive -> byte, median [ms]": r"^bridge_node\s+primitive -> first byte\s+\d+\s+([\d.]+)",
        "bridge Q line -> Imu, median [ms]": r"^bridge_node\s+Q line -> frog/imu\s+\d+\s+([\d.]+)",
    }),
]


def _run(cmd, cwd, timeout=1800) -> tuple[int, str, float, float]:
    t0, c0 = time.perf_counter(), os.times()
    r = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=timeout)
    c1 = os.times()
    return (r.returncode, r.stdout + r.stderr, time.perf_counter() - t0,
            (c1.children_user - c0.children_user) + (c1.children_system - c0.children_system))


def _worktree(base: str, keep: str | None) -> Path:
    path = Path(keep) if keep else Path(tempfile.mkdtemp(prefix="bench_base_"))
    if not (path / "dev").is_file():
        subprocess.run(["git", "worktree", "add", "--detach", "--force", str(path), base], cwd=ROOT, check=True,
                       capture_output=True)
    venv = path / ".venv"
    if not venv.exists():
        venv.symlink_to(ROOT / ".venv")
    print(f"base {base} in {path}; building its workspace ...", flush=True)
    rc, out, _, _ = _run([str(path / "dev"), "run", "true"], path)
    if rc:
        sys.exit(f"building the base tree failed:\n{out[-3000:]}")
    return path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--base", required=True, help="git revision measured as the baseline (e.g. 6cb0d55)")
    ap.add_argument("--repeats", type=int, default=3, help="runs of each bench per tree (medians)")
    ap.add_argument("--only", nargs="+", choices=[n for n, _, _ in FIGURES], help="these benches only")
    ap.add_argument("--keep", help="worktree directory of the base to create or reuse (default: a temp dir)")
    args = ap.parse_args(argv)
    trees = {"base": _worktree(args.base, args.keep), "this": ROOT}
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs", flush=True)
    failed = False
    rows = []
    for name, cmd, figures in FIGURES:
        if args.only and name not in args.only:
            continue
        got = {(side, fig): [] for side in trees for fig in figures}
        times = {side: [] for side in trees}
        for rep in range(args.repeats):
            order = list(trees) if rep % 2 == 0 else list(trees)[::-1]
            for side in order:
                tree = trees[side]
                rc, out, wall, cpu = _run([str(tree / "dev"), "run", "python", *cmd], tree)
                times[side].append((wall, cpu))
                for fig, rx in figures.items():
                    m = re.search(rx, out, re.M)
                    if m:
                        got[(side, fig)].append(float(m.group(1)))
                    else:
                        failed = True
                        print(f"  {name} ({side}, exit {rc}): no '{fig}' in its output:\n{out[-1500:]}", flush=True)
                print(f"  {name} repeat {rep + 1} {side}: {wall:.0f} s wall, {cpu:.0f} s CPU", flush=True)
        for fig in figures:
            b, t = got[("base", fig)], got[("this", fig)]
            if b and t:
                mb, mt = statistics.median(b), statistics.median(t)
                rows.append((fig, mb, mt, mt / mb if mb else float("nan"), len(b), len(t)))
    print(f"\n{'figure':40s} {'base':>10s} {'this':>10s} {'this/base':>9s}  n")
    for fig, mb, mt, ratio, nb, nt in rows:
        print(f"{fig:40s} {mb:10.4g} {mt:10.4g} {ratio:9.3f}  {nb}/{nt}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
