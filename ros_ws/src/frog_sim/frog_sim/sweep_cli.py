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
  frog-sweep calibrate --out runs/calibration                 # joint: hardware transitions + all speeds
  frog-sweep calibrate-replays --out runs/cal_replays         # N-period replays of all runs, CV, speeds
  frog-sweep calibrate --out runs/cal_quick --refine-iterations 10
  frog-sweep calibrate --body-drag-only --out runs/cbn        # the paper's C_bn in 0.8..2.0 only
  frog-sweep calibrate --body-drag-only --out runs/cal --candidates 0.6 0.8 1.0 --workers 2
  frog-sweep sweep --out runs/sweep                           # every EGaIn x frequency x phase
  frog-sweep sweep --out runs/sweep --scheduler tcp://host:8786
  frog-sweep sweep --out runs/sweep_quick --phases 0.3 0.5 0.7 --cycles 6

Interrupted runs resume from <out>/chunks when rerun with the same arguments.
"""


def _meta(args, extra: dict) -> dict:
    from frog_sim.core.model_parameters import FrogParameters
    from frog_common.version import code_version
    return {"created": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "code_version": code_version("frog_sim"),
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


def cmd_calibrate_any(args) -> int:
    return cmd_calibrate(args) if args.body_drag_only else cmd_calibrate_joint(args)


def _fmt_values(values: dict) -> str:
    return ", ".join(f"{k} = {v}" if isinstance(v, str) else f"{k} = {v:.4g}" for k, v in values.items())


def cmd_calibrate_joint(args) -> int:
    """Joint calibration: grid on the kick geometry, Nelder-Mead with the speeds."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from tqdm import tqdm

    from frog_sim import calibration as cal
    from frog_sim.core.actuation import ActuationLibrary, find_data_file
    from frog_sim.core.hardware_runs import HARDWARE_RUNS, estimate_tag_offset, read_hardware_runs
    from frog_sim.core.model_parameters import FrogParameters
    from frog_sim.fidelity import read_experiment_speeds
    from frog_sim.studies import measured_speeds
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t0, c0 = time.perf_counter(), time.process_time()
    folder = find_data_file("hardware_runs/line1.csv").parent
    logs = read_hardware_runs(folder, HARDWARE_RUNS)
    offset, offset_sd, n_off = estimate_tag_offset([logs["line1"], logs["line2"]])
    offset_deg = float(np.degrees(offset))
    train, targets, _ = cal.read_targets(folder, cal.TRAIN_RUNS, offset_deg)
    test, test_targets, _ = cal.read_targets(folder, cal.TEST_RUNS, offset_deg)
    cal_speeds = [(f, float(np.nanmean(list(v.values())))) for f, v in sorted(measured_speeds().items())]
    exp_speeds = [(e, f, v) for e, f, _, v in read_experiment_speeds()]
    lib = ActuationLibrary.load()
    base = FrogParameters().replace(**cal.PHYSICAL_BASE)
    common = dict(latency=args.latency, library=lib, cache_file=out / "evaluations.jsonl")
    quick = cal.JointObjective(targets, cal_speeds, exp_speeds, base, speeds=False, **common)
    full = cal.JointObjective(targets, cal_speeds, exp_speeds, base, speed_cycles=args.speed_cycles, **common)
    n_grid = int(np.prod([len(v) for v in cal.DEFAULT_GRID.values()]))
    bar = tqdm(total=n_grid + args.refine_iterations, desc="calibration", unit="eval")

    def progress(stage, ev):
        bar.update(1)
        bar.set_postfix_str(f"{stage} cost {ev.cost:.2f}")
    best, history = cal.coarse_to_fine(quick, cal.DEFAULT_GRID, full, cal.DEFAULT_REFINE_START,
                                       args.refine_iterations, progress)
    bar.close()
    grid_best = min((ev for st, ev in history if st == "grid"), key=lambda e: e.cost)
    # final numbers with the standard 8-cycle speeds; today's model for comparison
    final = cal.JointObjective(targets, cal_speeds, exp_speeds, base, speed_cycles=8, **common)
    ev_best = final(best.values)
    legacy_base = FrogParameters().replace(**cal.LEGACY_MODEL)
    legacy = cal.JointObjective(targets, cal_speeds, exp_speeds, legacy_base, speed_cycles=8, **common)
    legacy_vals = {k: getattr(legacy_base, k) for k in best.values}
    ev_legacy = legacy(legacy_vals)
    # cross-validation: held-out sines, transition terms only
    held = cal.JointObjective(test_targets, cal_speeds, exp_speeds, base, speeds=False, **common)
    held_legacy = cal.JointObjective(test_targets, cal_speeds, exp_speeds, legacy_base, speeds=False, **common)
    ev_held, ev_held_legacy = held(best.values), held_legacy(legacy_vals)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    print(f"tag offset from B on the line runs: {offset_deg:.1f} deg (sd {np.degrees(offset_sd):.1f}, n {n_off})")
    print(f"grid best (transitions + yaw only): {_fmt_values(grid_best.values)}; cost {grid_best.cost:.2f}")
    print(f"calibrated: {_fmt_values(ev_best.values)}")
    rows = sorted(k for k in ev_best.terms if not k.startswith("_"))
    print(f"\n{'term (1 = at tolerance)':28s} {'before':>8s} {'calibrated':>11s} {'held-out before':>15s} "
          f"{'held-out cal.':>14s}")
    for k in rows:
        print(f"{k:28s} {ev_legacy.terms.get(k, np.nan):8.2f} {ev_best.terms[k]:11.2f} "
              f"{ev_held_legacy.terms.get(k, np.nan):15.2f} {ev_held.terms.get(k, np.nan):14.2f}")
    print(f"{'total':28s} {ev_legacy.cost:8.2f} {ev_best.cost:11.2f} {ev_held_legacy.cost:15.2f} {ev_held.cost:14.2f}")
    print(f"speed RMS [mm/s]: calibration runs {1e3 * ev_legacy.terms['_rms_calibration_m_s']:.1f} -> "
          f"{1e3 * ev_best.terms['_rms_calibration_m_s']:.1f}, all experiments "
          f"{1e3 * ev_legacy.terms['_rms_experiments_m_s']:.1f} -> {1e3 * ev_best.terms['_rms_experiments_m_s']:.1f}")
    deg = np.degrees(1.0)
    print(f"\n{'prim':>4} {'n':>3} {'dh real':>8} {'before':>7} {'cal.':>7} | {'dy real':>8} {'before':>7} "
          f"{'cal.':>7} | {'dx real':>8} {'before':>7} {'cal.':>7}   (fit runs; deg, mm)")
    for p, t in targets.items():
        a, b = ev_legacy.sim["transitions"][p], ev_best.sim["transitions"][p]
        print(f"{p:>4} {t.n:3d} {deg * t.dheading:8.1f} {deg * a['dheading']:7.1f} {deg * b['dheading']:7.1f} | "
              f"{1e3 * t.dy:8.1f} {1e3 * a['dy']:7.1f} {1e3 * b['dy']:7.1f} | {1e3 * t.dx:8.1f} "
              f"{1e3 * a['dx']:7.1f} {1e3 * b['dx']:7.1f}")
    print(f"\n{len(history)} evaluations, {wall:.0f} s wall, {cpu:.0f} s CPU")
    result = {"tag_offset_deg": offset_deg, "base": cal.PHYSICAL_BASE, "calibrated": ev_best.values,
              "grid_best": grid_best.values, "terms": ev_best.terms, "cost": ev_best.cost,
              "before": {"values": legacy_vals, "terms": ev_legacy.terms, "cost": ev_legacy.cost},
              "cross_validation": {"fit_runs": list(cal.TRAIN_RUNS), "held_out_runs": list(cal.TEST_RUNS),
                                   "held_out_terms": ev_held.terms, "held_out_cost": ev_held.cost,
                                   "held_out_before_terms": ev_held_legacy.terms},
              "targets": {p: vars(t) for p, t in targets.items()},
              "held_out_targets": {p: vars(t) for p, t in test_targets.items()},
              "simulated": ev_best.sim, "history": [{"stage": st, "values": ev.values, "cost": ev.cost}
                                                    for st, ev in history],
              "wall_time_s": wall, "cpu_time_s": cpu}
    (out / "calibration.json").write_text(json.dumps(_meta(args, {"result": result}), indent=1, default=float))
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5))
    grid_evs = [ev for st, ev in history if st == "grid" and np.isfinite(ev.cost)]
    for i, name in enumerate(cal.DEFAULT_GRID):
        vals = sorted({ev.values[name] for ev in grid_evs})
        lo = [min(ev.cost for ev in grid_evs if ev.values[name] == v) for v in vals]
        x = np.linspace(0.0, 1.0, len(vals))
        axes[0].plot(x, lo, "-o", label=f"{name} {vals[0]}..{vals[-1]}")
    axes[0].set_xlabel("parameter, scaled to its grid (0 = lowest value)")
    axes[0].set_ylabel("lowest grid cost (transitions + yaw)")
    axes[0].legend(fontsize=7)
    axes[0].set_title("stage 1: grid")
    keys = rows
    xk = np.arange(len(keys))
    for j, (lab, ev) in enumerate((("before (fit runs)", ev_legacy), ("calibrated (fit runs)", ev_best),
                                   ("calibrated (held-out sines)", ev_held))):
        axes[1].bar(xk + 0.27 * (j - 1), [ev.terms.get(k, np.nan) for k in keys], 0.27, label=lab)
    axes[1].axhline(1.0, color="k", lw=0.8, ls="--")
    axes[1].set_yscale("log")
    axes[1].set_xticks(xk, keys, rotation=60, ha="right", fontsize=7)
    axes[1].set_ylabel("(error / tolerance)^2")
    axes[1].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "calibration.png", dpi=120)
    print(f"wrote {out / 'calibration.json'} and {out / 'calibration.png'}")
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


def cmd_calibrate_replays(args) -> int:
    """Joint calibration on N-period replays of every hardware run: grid, Nelder-Mead, leave-one-run-out CV."""
    from importlib.resources import files

    from tqdm import tqdm

    from frog_sim import multi_period as mp
    from frog_sim import replay_calibration as rc
    from frog_sim.core.actuation import find_data_file
    from frog_sim.core.hardware_runs import HARDWARE_RUNS, estimate_tag_offset, read_hardware_runs
    from frog_sim.core.model_parameters import FrogParameters
    from frog_sim.fidelity import read_experiment_speeds
    from frog_sim.studies import measured_speeds
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t0, c0 = time.perf_counter(), time.process_time()
    folder = find_data_file("hardware_runs/line1.csv").parent
    logs = read_hardware_runs(folder, HARDWARE_RUNS)
    offset, _, _ = estimate_tag_offset([logs["line1"], logs["line2"]])
    windows = mp.real_windows(logs, offset, max(rc.N_RATIO))
    cal_speeds = [(f, float(np.nanmean(list(v.values())))) for f, v in sorted(measured_speeds().items())]
    exp_speeds = [(e, f, v) for e, f, _, v in read_experiment_speeds()]
    base = FrogParameters()
    obj = rc.ReplayObjective(windows, cal_speeds, exp_speeds, base, latency=args.latency,
                             cache_file=out / "evaluations.jsonl")
    grid = rc.grid_points(rc.DEFAULT_GRID)
    before = dict(rc.PREVIOUS_MODEL)
    bar = tqdm(total=len(grid) + 1 + args.refine_iterations, desc="calibration", unit="eval")

    def progress(ev):
        bar.update(1)
        bar.set_postfix_str(f"cost {obj.cost(ev):.2f}")
    ev_before = obj.evaluate([before], progress=progress)[0]
    evs = obj.evaluate(grid, workers=args.workers or 1, progress=progress)
    scale = {n: float(np.ptp(v)) / max(len(v) - 1, 1) for n, v in rc.DEFAULT_GRID.items()}
    # Nelder-Mead from each of the best grid points (the objective is flat along the trade-off
    # between the friction and the linear damping: more than one start)
    starts = sorted(evs, key=obj.cost)[:max(args.starts, 1)]
    bar.total = len(grid) + 1 + args.refine_iterations * len(starts)
    for start in starts if args.refine_iterations > 0 else ():
        rc.refine(obj, start.values, scale, iterations=args.refine_iterations, progress=progress)
    bar.close()
    # every point evaluated (before, grid, refinements): the one meeting the most targets, then the cheapest
    candidates = list(obj.cache.values())
    best = min(candidates, key=obj.rank_key)
    cv = rc.cross_validate(obj, candidates)
    held = rc.held_out_summary(rc.held_out_windows(obj, candidates, cv))
    deg = np.degrees(1.0)

    def ratios(m):
        return "/".join(f"{m[n]['heading_ratio']:.2f}" if n in m else "-" for n in rc.N_RATIO)

    def row(label, ev, runs=None):
        m = obj.metrics(ev, runs)
        g = m["groups"]
        p = m["primitives"]
        return (f"{label:26s} " + " | ".join(f"{ratios(g.get(k, {})):19s}" for k in ("ellipse", "line/sine"))
                + f" | {deg * m['replays'][3]['rms_heading_error']:5.1f} | "
                + " ".join(f"{p[q]['dheading']:4.2f}" if q in p else "   -" for q in "CDEF")
                + " | " + " ".join(f"{p[q]['dy']:4.2f}" if q in p else "   -" for q in "EF")
                + f" | {p['B']['dx']:4.2f} | {m['distance'][4]:4.2f} | {abs(m['kick_ratio']):4.2f} | "
                + f"{deg * abs(m['repeated_yaw_rate']):5.1f} | {1e3 * m['speed_rms_experiments']:4.1f} "
                + f"{1e3 * m['speed_rms_calibration']:4.1f} | {obj.cost(ev, runs):7.2f}")
    missed = [k for k, ok in obj.targets(best).items() if not ok]
    print(f"\ncalibrated: {_fmt_values(best.values)} ({sum(obj.targets(best).values())} of "
          f"{len(obj.targets(best))} targets met; missed: {', '.join(missed) or 'none'})")
    head = (f"\n{'':26s} {'heading ratio N=1..4':19s} | {'':19s} | RMS dh3 | dh C D E F ratio | dy E F   | dx B | "
            f"d4   | kick | E rep | speed RMS | cost")
    print(head + f"\n{'':26s} {'ellipses':19s} | {'lines and sines':19s} |")
    print(row("before (all runs)", ev_before))
    print(row("calibrated (all runs)", best))
    for f in cv:
        chosen = obj.evaluate([f["chosen"]])[0]
        print(row(f"held out {'+'.join(f['held_out'])}", chosen, f["held_out"]))
    print(f"\nleave-one-run-out, every run scored with the point chosen without it: heading ratio N=1..4 "
          f"ellipses {ratios(held['groups'].get('ellipse', {}))}, lines and sines "
          f"{ratios(held['groups'].get('line/sine', {}))}, all {ratios(held['pooled'])}; RMS heading error at 3 "
          f"periods {deg * held['pooled'][3]['rms_heading_error']:.1f} deg; distance in 4 periods "
          f"{held['distance'][4]:.2f}")
    for f in cv:
        print(f"  held out {'+'.join(f['held_out']):10s} chosen on the other runs: {_fmt_values(f['chosen'])}")
    result = {"tag_offset_deg": float(np.degrees(offset)), "runs": list(HARDWARE_RUNS), "grid": rc.DEFAULT_GRID,
              "calibrated_raw": best.values,
              "calibrated": {k: float(f"{v:.4g}") for k, v in best.values.items()},
              "before": before, "terms": obj.terms(best), "metrics": rc._jsonable(obj.metrics(best)),
              "targets_met": obj.targets(best), "targets_met_before": obj.targets(ev_before),
              "terms_before": obj.terms(ev_before), "metrics_before": rc._jsonable(obj.metrics(ev_before)),
              "cross_validation": rc._jsonable(cv), "held_out": rc._jsonable(held),
              "evaluations": len(obj.cache),
              "wall_s": time.perf_counter() - t0, "cpu_s": time.process_time() - c0}
    record = _meta(args, {"result": result})
    (out / "calibration_replays.json").write_text(json.dumps(record, indent=1, default=float))
    print(f"\n{len(obj.cache)} evaluations, {time.perf_counter() - t0:.0f} s wall; "
          f"wrote {out / 'calibration_replays.json'}")
    if args.write_package_data:
        target = Path(str(files("frog_sim").joinpath("data", "replay_calibration.json")))
        shipped = {"what": "frog-sweep calibrate-replays: joint calibration on N = 1..4 period replays of the "
                           "hardware runs and all speeds, leave-one-run-out cross-validation; the calibrated values "
                           "are FrogParameters defaults",
                   "command": "frog-sweep " + " ".join(sys.argv[1:]),
                   "created": record["created"], "code_version": record["code_version"], **result}
        target.write_text(json.dumps(shipped, indent=1, default=float) + "\n")
        print(f"wrote {target} (package data)")
    return 0


def build_parser():
    ap = argparse.ArgumentParser(prog="frog-sweep", description=__doc__, epilog=EPILOG,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="command", required=True)

    def common(p):
        p.add_argument("--out", type=Path, required=True, help="run folder")
        p.add_argument("--cycles", type=int, default=8, help="gait cycles per simulation")
        p.add_argument("--workers", type=int, help="local processes (default: all cores)")
        p.add_argument("--scheduler", help="Dask scheduler address, e.g. tcp://host:8786")

    c = sub.add_parser("calibrate", help="joint calibration vs hardware transitions and speeds "
                                         "(--body-drag-only: C_bn vs the 10 %% runs, as the paper)",
                       epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    common(c)
    c.add_argument("--body-drag-only", action="store_true",
                   help="the paper's calibration: grid of C_bn vs the 10 %% EGaIn calibration runs")
    c.add_argument("--candidates", type=float, nargs="+",
                   default=[round(x, 2) for x in np.arange(0.8, 2.0001, 0.1)],
                   help="C_bn values of --body-drag-only")
    c.add_argument("--refine-iterations", type=int, default=30,
                   help="Nelder-Mead evaluations of the full objective after the grid (default 30)")
    c.add_argument("--speed-cycles", type=int, default=6,
                   help="gait cycles per speed simulation during the search (default 6)")
    c.add_argument("--latency", type=float, default=0.10, help="decision -> firing [s] (default 0.10)")
    c.set_defaults(func=cmd_calibrate_any)
    r = sub.add_parser("calibrate-replays", help="joint calibration on N-period hardware replays and all speeds, "
                                                 "with leave-one-run-out cross-validation",
                       epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    r.add_argument("--out", type=Path, required=True, help="run folder (evaluations.jsonl resumes a rerun)")
    r.add_argument("--workers", type=int, default=1, help="local processes for the grid (default 1)")
    r.add_argument("--refine-iterations", type=int, default=10,
                   help="Nelder-Mead evaluations after the grid, per start (default 10)")
    r.add_argument("--starts", type=int, default=2,
                   help="Nelder-Mead starts: the best grid points (default 2)")
    r.add_argument("--latency", type=float, default=0.10, help="decision -> firing [s] (default 0.10)")
    r.add_argument("--write-package-data", action="store_true",
                   help="also write the record to frog_sim/data/replay_calibration.json (what the tests read)")
    r.set_defaults(func=cmd_calibrate_replays)
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
