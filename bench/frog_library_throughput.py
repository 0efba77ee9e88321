"""Motion-library throughput: simulated transitions per second, and the paper-size projection.

Generates (1) a small library with 1 and with 2 local workers (scaling), and (2) a slice of
the paper-size library (default 10 %: 850 of 8503 states = 7,650 transitions, 3 s
horizon) with all workers, then projects the wall time of the full 76,527 transitions.
Targets: paper size <= 60 min on this 2-core machine, stretch <= 20 min.

    ./dev bench frog_library_throughput                  # 10 % slice (~10+ minutes)
    ./dev bench frog_library_throughput --slice-states 100 --scaling-states 20   # quick look
"""

import argparse
import os
import shutil
import tempfile
import time
from pathlib import Path

from frog_sim.core.motion_library import LibrarySpec, generate_library

PAPER_STATES = 8503
PAPER_TRANSITIONS = 76527


def timed_generate(n_states: int, workers: int, work: Path, seed: int) -> float:
    spec = LibrarySpec(n_states=n_states, horizon=3.0, seed=seed)
    out = work / f"lib_{n_states}_{workers}_{seed}.npz"
    t0 = time.perf_counter()
    generate_library(spec, out, workers=workers, chunk_size=max(1, min(25, n_states // (2 * workers))),
                     progress=True)
    return time.perf_counter() - t0


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--slice-states", type=int, default=850, help="states of the slice (10 %% = 850)")
    ap.add_argument("--scaling-states", type=int, default=120,
                    help="states of the 1- and 2-worker runs (large enough to amortise worker start-up)")
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--skip-slice", action="store_true", help="only the 1- vs 2-worker scaling")
    args = ap.parse_args()
    cores = os.cpu_count() or 1
    work = Path(tempfile.mkdtemp(prefix="frog_lib_bench_"))
    try:
        # warm the numba cache and the actuation fit once, outside the timings
        timed_generate(2, 1, work, seed=99)
        rates = {}
        for w in sorted({1, min(2, cores)}):
            walls = [timed_generate(args.scaling_states, w, work, seed=r) for r in range(args.repeats)]
            wall = sorted(walls)[len(walls) // 2]
            rates[w] = 9 * args.scaling_states / wall
            print(f"scaling run: {args.scaling_states} states x 9 primitives with {w} worker(s): "
                  f"{wall:.1f} s -> {rates[w]:.2f} transitions/s")
        if len(rates) == 2:
            print(f"speed-up 1 -> 2 workers: {rates[2] / rates[1]:.2f}x (ideal 2.00x)")
        if args.skip_slice:
            return
        wall = timed_generate(args.slice_states, cores, work, seed=1000)
        n = 9 * args.slice_states
        rate = n / wall
        projected = PAPER_TRANSITIONS / rate
        print(f"\nslice: {args.slice_states} states ({100 * args.slice_states / PAPER_STATES:.1f} % of the "
              f"paper's {PAPER_STATES}) = {n} transitions, 3.0 s horizon, {cores} workers: "
              f"{wall:.0f} s wall -> {rate:.2f} transitions/s")
        print(f"projected paper-size library ({PAPER_TRANSITIONS} transitions): {projected / 60:.1f} min "
              f"(target <= 60 min: ratio {projected / 3600:.2f}; stretch <= 20 min: ratio "
              f"{projected / 1200:.2f})")
        print(f"simulated seconds per wall second over all workers: {rate * 3.0 / 2:.1f} "
              f"(mirror pairs: every second transition is an exact reflection, so "
              f"{rate / 2:.2f} simulations/s; without mirror pairs the projection would be "
              f"{2 * projected / 60:.1f} min)")
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
