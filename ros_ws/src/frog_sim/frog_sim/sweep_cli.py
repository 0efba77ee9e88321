"""``frog-sweep``: drag calibration and the design / gait sweep of the frog (paper Fig. 4)."""

from __future__ import annotations

import argparse
import csv
import json
import sys
import time
from pathlib import Path

import numpy as np

EPILOG = """examples:
  frog-sweep calibrate --out runs/calibration                 # C_bn in 0.8..2.0 vs calibration runs
  frog-sweep calibrate --out runs/cal --candidates 0.6 0.8 1.0 --workers 2
  frog-sweep sweep --out runs/sweep                           # every EGaIn x frequency x phase
  frog-sweep sweep --out runs/sweep --scheduler tcp://host:8786
  frog-sweep sweep --out runs/sweep_quick --phases 0.3 0.5 0.7 --cycles 6

Interrupted runs resume from <out>/chunks when rerun with the same arguments.
"""


def _meta(args, extra: dict) -> dict:
    from frog_sim.core.model_parameters import FrogParameters
    from frog_sim.core.motion_library import code_version
    return {"created": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "code_version": code_version(),
            "arguments": {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()
                          if k != "func"},
            "robot_defaults": FrogParameters().as_dict(), **extra}


def cmd_calibrate(args) -> int:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from frog_sim.sweeps import calibrate_body_drag
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    res = calibrate_body_drag(candidates=args.candidates, work_dir=out / "chunks",
                              cycles=args.cycles, workers=args.workers, scheduler=args.scheduler)
    wall = time.perf_counter() - t0
    print(f"\n{'C_bn':>6} {'RMS speed error [cm/s]':>24}")
    for c, r in zip(res.candidates, res.rms):
        mark = "  <- best" if c == res.best else ""
        print(f"{c:6.2f} {100 * r:24.3f}{mark}")
    k = res.best_index
    print(f"\nfitted C_bn = {res.best:.2f} (paper: 0.8), RMS error {100 * res.rms[k]:.2f} cm/s "
          f"over {len(res.frequencies)} frequencies; {wall:.0f} s wall")
    print(f"\n{'f [Hz]':>7} {'measured [cm/s]':>16} {'simulated [cm/s]':>17}")
    for f, m, s in zip(res.frequencies, res.measured, res.simulated[k]):
        print(f"{f:7.2f} {100 * m:16.2f} {100 * s:17.2f}")
    result = {"best_body_drag_normal": res.best, "rms_error_m_per_s": float(res.rms[k]),
              "candidates": res.candidates.tolist(), "rms_m_per_s": res.rms.tolist(),
              "frequencies_hz": res.frequencies.tolist(), "measured_m_per_s": res.measured.tolist(),
              "simulated_m_per_s": res.simulated.tolist(), "wall_time_s": wall}
    (out / "calibration.json").write_text(json.dumps(_meta(args, {"result": result}), indent=1))
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    axes[0].plot(res.frequencies, 100 * res.measured, "ko", label="measured (calibration runs)")
    for i in sorted({0, k, len(res.candidates) - 1}):
        axes[0].plot(res.frequencies, 100 * res.simulated[i], "-o", ms=3,
                     label=f"simulated, C_bn = {res.candidates[i]:.2f}")
    axes[0].set_xlabel("frequency [Hz]")
    axes[0].set_ylabel("steady forward speed [cm/s]")
    axes[0].set_title("10 % EGaIn, phase offset 0.5")
    axes[0].legend(fontsize=8)
    axes[1].plot(res.candidates, 100 * res.rms, "-o")
    axes[1].set_xlabel("body normal drag coefficient C_bn")
    axes[1].set_ylabel("RMS speed error [cm/s]")
    axes[1].set_title(f"best C_bn = {res.best:.2f}")
    fig.tight_layout()
    fig.savefig(out / "calibration.png", dpi=120)
    print(f"\nwrote {out / 'calibration.json'} and {out / 'calibration.png'}")
    return 0


def cmd_sweep(args) -> int:
    from frog_sim.sweeps import SmaPulseEnergy, design_sweep
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    energy = SmaPulseEnergy(battery_voltage=args.voltage, wire_resistance=args.resistance,
                            pulse=args.pulse)
    t0 = time.perf_counter()
    rows = design_sweep(work_dir=out / "chunks", phases=args.phases, egains=args.egains,
                        energy=energy, body_drag_normal=args.body_drag_normal,
                        cycles=args.cycles, workers=args.workers, scheduler=args.scheduler)
    wall = time.perf_counter() - t0
    meta = _meta(args, {"energy_model": {"battery_voltage_v": energy.battery_voltage,
                                         "wire_resistance_ohm": energy.wire_resistance,
                                         "pulse_s": energy.pulse, "current_a": energy.current,
                                         "energy_per_pulse_j": energy.energy_per_pulse,
                                         "pulses_per_cycle": energy.limbs_per_cycle},
                        "units": {"egain_vol_pct": "%", "frequency_hz": "Hz", "phase_offset": "-",
                                  "speed_m_per_s": "m/s", "mass_kg": "kg", "input_power_w": "W",
                                  "cost_of_transport": "-"},
                        "wall_time_s": wall, "rows": len(rows)})
    with open(out / "sweep.csv", "w", newline="") as f:
        for line in json.dumps(meta, indent=1).splitlines():
            f.write(f"# {line}\n")
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    print_ranking(rows)
    print(f"\nsweep of {len(rows)} gaits in {wall:.0f} s wall")
    plot_sweep(rows, out / "sweep.png")
    print(f"wrote {out / 'sweep.csv'} and {out / 'sweep.png'}")
    return 0


def print_ranking(rows, n: int = 5) -> None:
    fast = sorted(rows, key=lambda r: -r["speed_m_per_s"])[:n]
    eff = sorted((r for r in rows if r["speed_m_per_s"] > 0), key=lambda r: r["cost_of_transport"])[:n]
    for title, sel in (("fastest designs (paper: 30 % EGaIn at 1.3-1.4 Hz, 4.7-4.8 cm/s)", fast),
                       ("most efficient designs (paper: 10 % EGaIn at 0.4-0.5 Hz, COT 158-165)", eff)):
        print(f"\n{title}")
        print(f"{'EGaIn %':>8} {'f [Hz]':>7} {'phase':>6} {'speed [cm/s]':>13} {'COT':>8}")
        for r in sel:
            print(f"{r['egain_vol_pct']:8.0f} {r['frequency_hz']:7.2f} {r['phase_offset']:6.1f} "
                  f"{100 * r['speed_m_per_s']:13.2f} {r['cost_of_transport']:8.1f}")


def plot_sweep(rows, png) -> None:
    """Paper Fig. 4 style: speed and COT vs frequency per EGaIn (phase 0.5), speed vs phase."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    egains = sorted({r["egain_vol_pct"] for r in rows})
    phases = sorted({r["phase_offset"] for r in rows})
    ref_phase = min(phases, key=lambda p: abs(p - 0.5))
    fig, axes = plt.subplots(2, 2, figsize=(12, 8.5))
    cmap = plt.get_cmap("viridis")
    for i, e in enumerate(egains):
        col = cmap(i / max(1, len(egains) - 1))
        sel = sorted((r for r in rows if r["egain_vol_pct"] == e and r["phase_offset"] == ref_phase),
                     key=lambda r: r["frequency_hz"])
        f = [r["frequency_hz"] for r in sel]
        axes[0, 0].plot(f, [100 * r["speed_m_per_s"] for r in sel], "-o", ms=3, color=col,
                        label=f"{e:.0f} % EGaIn")
        axes[0, 1].plot(f, [r["cost_of_transport"] for r in sel], "-o", ms=3, color=col)
        best_f = max(sel, key=lambda r: r["speed_m_per_s"])["frequency_hz"]
        by_phase = sorted((r for r in rows if r["egain_vol_pct"] == e and r["frequency_hz"] == best_f),
                          key=lambda r: r["phase_offset"])
        axes[1, 0].plot([r["phase_offset"] for r in by_phase],
                        [100 * r["speed_m_per_s"] for r in by_phase], "-o", ms=3, color=col,
                        label=f"{e:.0f} % at {best_f:.1f} Hz")
    axes[0, 0].set(xlabel="frequency [Hz]", ylabel="speed [cm/s]",
                   title=f"steady speed, phase offset {ref_phase:.1f}")
    axes[0, 0].legend(fontsize=8)
    axes[0, 1].set(xlabel="frequency [Hz]", ylabel="cost of transport [-]", yscale="log",
                   title=f"COT, phase offset {ref_phase:.1f}")
    axes[1, 0].set(xlabel="phase offset [-]", ylabel="speed [cm/s]",
                   title="speed vs phase at each EGaIn's fastest frequency")
    axes[1, 0].legend(fontsize=8)
    ax = axes[1, 1]
    grid = np.full((len(egains), len(phases)), np.nan)
    for r in rows:
        i, j = egains.index(r["egain_vol_pct"]), phases.index(r["phase_offset"])
        grid[i, j] = np.nanmax([grid[i, j], 100 * r["speed_m_per_s"]])
    im = ax.imshow(grid, aspect="auto", origin="lower", cmap="magma")
    ax.set_xticks(range(len(phases)), [f"{p:.1f}" for p in phases])
    ax.set_yticks(range(len(egains)), [f"{e:.0f}" for e in egains])
    ax.set(xlabel="phase offset", ylabel="EGaIn %", title="best speed over frequency [cm/s]")
    fig.colorbar(im, ax=ax)
    fig.tight_layout()
    fig.savefig(png, dpi=120)
    plt.close(fig)


def build_parser():
    ap = argparse.ArgumentParser(prog="frog-sweep", description=__doc__, epilog=EPILOG,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="command", required=True)

    def common(p):
        p.add_argument("--out", type=Path, required=True, help="run folder")
        p.add_argument("--cycles", type=int, default=8, help="gait cycles per simulation")
        p.add_argument("--workers", type=int, help="local processes (default: all cores)")
        p.add_argument("--scheduler", help="Dask scheduler address, e.g. tcp://host:8786")

    c = sub.add_parser("calibrate", help="fit C_bn to the 10 %% EGaIn calibration runs")
    common(c)
    c.add_argument("--candidates", type=float, nargs="+",
                   default=[round(x, 2) for x in np.arange(0.8, 2.0001, 0.1)])
    c.set_defaults(func=cmd_calibrate)
    s = sub.add_parser("sweep", help="speed and COT over EGaIn x frequency x phase")
    common(s)
    s.add_argument("--phases", type=float, nargs="+", default=None, help="default 0.0..0.9")
    s.add_argument("--egains", type=float, nargs="+", default=None, help="default all measured")
    s.add_argument("--body-drag-normal", type=float, default=None, help="C_bn (default: model's)")
    s.add_argument("--voltage", type=float, default=11.1, help="battery voltage [V]")
    s.add_argument("--resistance", type=float, default=2.0, help="SMA loop resistance [ohm]")
    s.add_argument("--pulse", type=float, default=0.080, help="heating pulse [s]")
    s.set_defaults(func=cmd_sweep)
    return ap


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    from frog_sim.core.batch import BatchError
    try:
        return args.func(args)
    except (BatchError, ValueError, OSError) as exc:
        print(f"frog-sweep: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("frog-sweep: interrupted; rerun the same command to resume", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
