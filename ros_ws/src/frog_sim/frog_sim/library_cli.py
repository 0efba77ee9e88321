"""``frog-library``: generate, inspect and plot the frog's motion-primitive library."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

EPILOG = """examples:
  frog-library generate --states 200 --horizon 3.0 --out runs/lib/small.npz
  frog-library generate --states 8503 --out runs/lib/paper.npz          # paper size, resumable
  frog-library generate --states 8503 --out runs/lib/paper.npz --scheduler tcp://host:8786
  frog-library generate --states 200 --out runs/lib/no_friction.npz --set waterline_friction=0 \\
      --set yaw_damping_linear=0.000375 --set surge_damping_linear=0.0483   # the model without waterline friction
  frog-library info runs/lib/small.npz
  frog-library plot runs/lib/small.npz --out runs/lib/small_transitions.png --period 1.5

An interrupted 'generate' resumes from its chunk folder (<out>.chunks) when rerun with the
same arguments; the finished file is bit-identical whatever the number of workers.
"""


def cmd_generate(args) -> int:
    from frog_sim.cli import parse_overrides
    from frog_sim.core.motion_library import LibrarySpec, generate_library
    spec = LibrarySpec(n_states=args.states, horizon=args.horizon,
                       sample_interval=args.sample_interval, seed=args.seed,
                       params={"egain_vol_pct": args.egain, **parse_overrides(args.set)}, mirror=not args.no_mirror)
    spec.validate()
    path = generate_library(spec, args.out, work_dir=args.work_dir, workers=args.workers,
                            scheduler=args.scheduler, chunk_size=args.chunk_size)
    print(f"wrote {path}")
    cmd_info(argparse.Namespace(file=path))
    if not args.no_plot:
        png = Path(args.out).with_suffix(".png")
        plot_transitions(path, png, period=min(1.5, args.horizon))
        print(f"plot: {png}")
    return 0


def cmd_info(args) -> int:
    from frog_common.motion_library_file import load_motion_library
    lib = load_motion_library(args.file)
    meta = lib.metadata
    p, n, t, _ = lib.transitions.shape
    conv = lib.converged
    print(f"file:        {args.file}")
    print(f"primitives:  {p} ({' '.join(str(x) for x in lib.primitive_names)})")
    print(f"states:      {n}   transitions: {p * n}   failed: {int((~conv).sum())}   simulated: "
          f"{meta['sampling'].get('simulated_transitions', p * n)} (mirror pairs: "
          f"{meta['sampling'].get('mirror_pairs', False)})")
    print(f"horizon:     {meta['horizon_s']} s, {t} samples every {meta['sample_interval_s']} s")
    s = meta["sampling"]
    print(f"sampling:    seed {s['seed']}, forward {s['forward_velocity_range']} m/s, lateral "
          f"{s['lateral_velocity_range']} m/s, yaw rate {np.round(s['yaw_rate_range'], 4).tolist()} rad/s")
    print(f"robot:       EGaIn {meta['robot'].get('egain_vol_pct')} %, hash {meta['robot_hash'][:16]}")
    print(f"code:        {meta['code_version']}, created {meta['created']}")
    if "generation_wall_time_s" in meta:
        rate = p * n / meta["generation_wall_time_s"]
        print(f"generation:  {meta['generation_wall_time_s']:.1f} s wall ({rate:.1f} transitions/s)")
    final = lib.transitions[:, :, -1, :]
    print("mean final displacement per primitive (x forward, y left) [cm] and heading [deg]:")
    for k, name in enumerate(lib.primitive_names):
        f = final[k][conv[k]]
        print(f"  {name}: x {100 * f[:, 0].mean():6.2f}  y {100 * f[:, 1].mean():6.2f}  "
              f"heading {np.degrees(f[:, 2]).mean():7.2f}")
    return 0


def plot_transitions(path, png, period: float = 1.5, n_sample: int = 1000, seed: int = 0):
    """Fig. S2d analogue: end positions and headings of random transitions at ``period``."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from frog_common.motion_library_file import load_motion_library
    lib = load_motion_library(path)
    times = lib.times
    k = int(np.argmin(np.abs(times - period)))
    p, n = lib.converged.shape
    rng = np.random.default_rng(seed)
    pairs = np.argwhere(lib.converged)
    pick = pairs[rng.choice(len(pairs), size=min(n_sample, len(pairs)), replace=False)]
    fig, ax = plt.subplots(figsize=(7.5, 7))
    cmap = plt.get_cmap("tab10")
    for prim in range(p):
        sel = pick[pick[:, 0] == prim]
        st = lib.transitions[sel[:, 0], sel[:, 1], k]
        ax.quiver(100 * st[:, 0], 100 * st[:, 1], np.cos(st[:, 2]), np.sin(st[:, 2]),
                  color=cmap(prim), angles="xy", scale=40, width=0.003,
                  label=str(lib.primitive_names[prim]))
    ax.plot(0, 0, "k+", ms=14)
    ax.set_aspect("equal")
    ax.set_xlabel("x [cm] (start body frame, forward)")
    ax.set_ylabel("y [cm] (left)")
    ax.set_title(f"{len(pick)} random transitions after {times[k]:.2f} s: position and heading")
    ax.legend(title="primitive", ncol=3, fontsize=8)
    fig.tight_layout()
    fig.savefig(png, dpi=120)
    plt.close(fig)


def cmd_plot(args) -> int:
    plot_transitions(args.file, args.out, period=args.period, n_sample=args.samples)
    print(f"plot: {args.out}")
    return 0


def build_parser():
    ap = argparse.ArgumentParser(prog="frog-library", description=__doc__, epilog=EPILOG,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="command", required=True)
    g = sub.add_parser("generate", help="simulate the library (resumable, parallel)")
    g.add_argument("--states", type=int, default=200, help="initial states N (paper 8503)")
    g.add_argument("--horizon", type=float, default=3.0, help="simulated time per transition [s]")
    g.add_argument("--sample-interval", type=float, default=0.05, help="state sample spacing [s]")
    g.add_argument("--seed", type=int, default=0)
    g.add_argument("--egain", type=float, default=10.0, help="EGaIn volume %% of the limbs")
    g.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="another robot model: override a FrogParameters field (repeatable), e.g. "
                        "yaw_damping_linear=0")
    g.add_argument("--out", type=Path, required=True)
    g.add_argument("--work-dir", type=Path, help="chunk folder (default <out>.chunks)")
    g.add_argument("--workers", type=int, help="local processes (default: all cores)")
    g.add_argument("--scheduler", help="Dask scheduler address, e.g. tcp://host:8786")
    g.add_argument("--chunk-size", type=int, default=25, help="initial states per chunk")
    g.add_argument("--no-plot", action="store_true")
    g.add_argument("--no-mirror", action="store_true",
                   help="simulate every state (default: mirror pairs, half the simulations)")
    g.set_defaults(func=cmd_generate)
    i = sub.add_parser("info", help="summary of a library file")
    i.add_argument("file", type=Path)
    i.set_defaults(func=cmd_info)
    p = sub.add_parser("plot", help="plot random transitions (paper Fig. S2d)")
    p.add_argument("file", type=Path)
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--period", type=float, default=1.5, help="time of the plotted states [s]")
    p.add_argument("--samples", type=int, default=1000)
    p.set_defaults(func=cmd_plot)
    return ap


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    from frog_sim.core.batch import BatchError
    from frog_common.motion_library_file import LibraryFormatError
    from frog_sim.cli import CliError
    try:
        return args.func(args)
    except (LibraryFormatError, BatchError, ValueError, OSError, CliError) as exc:
        print(f"frog-library: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("frog-library: interrupted; rerun the same command to resume", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
