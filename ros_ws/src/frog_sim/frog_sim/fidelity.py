"""The simulator against the real robot: ``frog-sim fidelity``.

What is compared (all from ``shared/data/frog``):

* **Transitions** (``hardware_runs/``): every reconstructed decision of the nine
  closed-loop runs (:mod:`frog_sim.core.hardware_runs`) is simulated from the same body
  velocity (eq. 13) with the same primitive, fired ``latency`` after the decision, for
  the run's decision period. Per primitive: mean, sd, n of dx, dy, dheading, real and
  simulated, and their ratio.
* **Kick response**: heading after each single-side kick (E, F; E mirrored onto F's
  sign), mean real curve vs mean simulated curve over one period; the
  peak yaw rate and the yaw rate left at the next decision (both as the real logs
  allow: local fits). From rest, a single E kick: the yaw rate 1.5 s after firing vs
  its peak (target <= 30 %).
* **Repeated kicks**: E every period from rest: steady yaw rate and the time to 63 %.
* **N-period replays**: the robot's logged primitive sequence replayed open loop from each
  decision's measured state for N = 1..5 periods (:mod:`frog_sim.multi_period`): heading
  ratio, RMS heading and position error vs N, pooled, on the ellipses (sustained turns) and
  on the lines and sines, and per run.
* **Coasting**: 25 mm/s forward with no kick: speed after 5 s and 20 s, distance in 60 s.
* **Speeds**: steady speed (phase 0.5) vs the 10 % calibration runs and vs every
  experiment speed (``experiment_speeds.csv``); the fastest and the most efficient design
  of the simulated grid vs the paper (30 % at 1.3-1.4 Hz; 10 % at 0.4-0.5 Hz).

The real robot's figures (heading about 14 deg per turning period, peak yaw ~40 deg/s, E/F
repeated: 13.5 deg/s, 63 % after 2.3 s) are measured from the logs with the same code for
both sides.
"""
from __future__ import annotations

import csv
import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
from frog_common.primitives import PRIMITIVE_NAMES

from .core import hardware_runs as hr
from .core.actuation import ActuationLibrary, find_data_file
from .core.model_parameters import FrogParameters
from .core.schedules import ActivationSchedule
from .core.simulation import DEFAULT_TIME_STEP, FrogSimulation

EXPERIMENT_SPEEDS_FILE = 'experiment_speeds.csv'
TURNING = tuple('CDEFGH')
#: Paper (Results): fastest 30 % at 1.3-1.4 Hz, most efficient 10 % at 0.4-0.5 Hz (phase 0.5).
PAPER_FASTEST = {(30.0, 1.3), (30.0, 1.4)}
PAPER_MOST_EFFICIENT = {(10.0, 0.4), (10.0, 0.5)}


@dataclass
class FidelityConfig:
    """How the comparison is run (not physics).

    Attributes
    ----------
    latency : float
        Decision -> firing [s]: the BLE relay (README: the heading starts to change
        0.15-0.2 s after a decision; the SMA's own delay is in the eq. 9 profile).
    time_step : float
        Simulator dt [s].
    tag_offset_deg : float or None
        Robot heading = theta + offset; None: estimated from B on the line runs.
    runs : tuple of str
        Hardware runs to use.
    speeds : bool
        Include the speed comparisons (the slow part).
    """

    latency: float = hr.DECISION_TO_FIRING_S
    time_step: float = DEFAULT_TIME_STEP
    tag_offset_deg: float | None = None
    runs: tuple = hr.HARDWARE_RUNS
    speeds: bool = True
    coast_speed: float = 0.025
    coast_duration: float = 60.0
    repeat_periods: int = 12
    replay_periods: int = 5


# ------------------------------------------------------------------ real data
def real_transitions(folder: Path | str, runs=hr.HARDWARE_RUNS, tag_offset_deg=None):
    """Transitions of the hardware runs and the fits behind them.

    Returns
    -------
    transitions : list of Transition
    info : dict
        Per-run decision fits and the tag offset used.
    """
    logs = hr.read_hardware_runs(folder, runs)
    lines = [log for name, log in logs.items() if name.startswith('line')]
    if tag_offset_deg is None:
        mean, sd, n = hr.estimate_tag_offset(lines or list(logs.values()))
        offset = mean
        offset_info = {'estimated_deg': float(np.degrees(mean)), 'sd_deg': float(np.degrees(sd)), 'n': n}
    else:
        offset = np.radians(tag_offset_deg)
        offset_info = {'given_deg': float(tag_offset_deg)}
    out, fits = [], {}
    for name, log in logs.items():
        fit = hr.fit_decision_times(log)
        fits[name] = {'period_s': fit.period, 't0_s': fit.t0, 'residual_rms_s': fit.residual_rms,
                      'residual_max_s': fit.residual_max, 'frame_interval_s': fit.frame_interval,
                      'changes': len(fit.change_times), 'dropped_burst_rows': log.dropped_rows}
        trs = hr.measure_transitions(log, fit, tag_offset=offset)
        for a, b in zip(trs[:-1], trs[1:]):   # yaw rate left at the next decision
            if b.index == a.index + 1:
                a.extra['yaw_rate_next'] = b.yaw_rate
        for tr in trs:
            if tr.primitive in ('E', 'F'):
                tau, dh, r = hr.heading_curve(log, tr.time, tr.period, tag_offset=offset)
                tr.extra['curve'] = {'tau': tau.tolist(), 'dheading': dh.tolist(), 'yaw_rate': r.tolist()}
        out += trs
    return out, {'runs': fits, 'tag_offset': offset_info, 'tag_offset_rad': float(offset)}


# ------------------------------------------------------------------ simulation
def _heading_slope(traj, t_end, before=0.45, after=0.05):
    sel = (traj.time >= t_end - before) & (traj.time <= t_end + after)
    return float(np.polyfit(traj.time[sel] - t_end, traj.heading[sel], 1)[0])


def _smoothed_yaw_rate(traj, half=0.15):
    """Yaw rate as the real logs allow: slope of a local quadratic over +-0.15 s."""
    out = np.full(traj.time.shape, np.nan)
    for i, t in enumerate(traj.time):
        sel = np.abs(traj.time - t) <= half
        if sel.sum() >= 4:
            out[i] = np.polyfit(traj.time[sel] - t, traj.heading[sel], 2)[1]
    return out


def simulate_transition(sim: FrogSimulation, tr: hr.Transition, latency: float, curve: bool = False):
    """The simulated counterpart of one real decision (same start velocity and primitive)."""
    sim.reset()
    sched = (ActivationSchedule.empty() if tr.primitive == 'I'
             else ActivationSchedule.primitive(tr.primitive, latency, sim.params.pulse_duration))
    sim.set_schedule(sched)
    sim.set_velocity(tr.forward, tr.lateral, tr.yaw_rate)
    traj = sim.run(tr.period + 0.05, record_interval=0.01)
    i = int(np.argmin(np.abs(traj.time - tr.period)))
    h0 = traj.heading[0]
    c, s = np.cos(h0), np.sin(h0)
    e = traj.com[i] - traj.com[0]
    out = hr.Transition(run=tr.run, index=tr.index, time=tr.time, period=tr.period, primitive=tr.primitive,
                        previous=tr.previous, forward=tr.forward, lateral=tr.lateral, yaw_rate=tr.yaw_rate,
                        dx=float(c * e[0] + s * e[1]), dy=float(-s * e[0] + c * e[1]),
                        dheading=float(traj.heading[i] - h0))
    out.extra['yaw_rate_next'] = _heading_slope(traj, tr.period)
    if curve:
        sel = traj.time <= tr.period + 1e-9
        out.extra['curve'] = {'tau': traj.time[sel].tolist(), 'dheading': (traj.heading[sel] - h0).tolist(),
                              'yaw_rate': _smoothed_yaw_rate(traj)[sel].tolist()}
    return out


def kick_from_rest(sim: FrogSimulation, primitive: str = 'E', duration: float = 4.0) -> dict:
    """Single kick at t = 0 from rest: heading, (smoothed) yaw rate, peak and decay."""
    sim.reset()
    sim.set_schedule(ActivationSchedule.primitive(primitive, 0.0, sim.params.pulse_duration))
    traj = sim.run(duration, record_interval=0.01)
    r = _smoothed_yaw_rate(traj)
    k = int(np.nanargmax(np.abs(r)))
    peak = float(r[k])
    i15 = int(np.argmin(np.abs(traj.time - 1.5)))
    below = np.nonzero((traj.time > traj.time[k]) & (np.abs(r) < 0.1 * abs(peak)))[0]
    return {'primitive': primitive, 'tau': traj.time.tolist(), 'dheading': (traj.heading - traj.heading[0]).tolist(),
            'yaw_rate': r.tolist(), 'peak_yaw_rate': peak, 'peak_time': float(traj.time[k]),
            'yaw_rate_at_1p5s': float(r[i15]), 'ratio_at_1p5s': float(r[i15] / peak) if peak else np.nan,
            'time_below_10pct': float(traj.time[below[0]]) if below.size else None,
            'heading_change_total': float(traj.heading[-1] - traj.heading[0])}


def repeated_kicks(sim: FrogSimulation, primitive: str = 'E', period: float = 1.43, n: int = 12) -> dict:
    """``primitive`` every ``period`` from rest: per-period mean yaw rate, steady value, t63."""
    sim.reset()
    sim.set_schedule(ActivationSchedule.primitive_sequence([primitive] * n, period=period,
                                                           pulse=sim.params.pulse_duration))
    traj = sim.run(n * period, record_interval=0.01)
    ends = period * np.arange(1, n + 1)
    h = np.interp(np.concatenate([[0.0], ends]), traj.time, traj.heading)
    rate = np.diff(h) / period
    steady = float(np.mean(rate[-4:]))
    target = 0.63 * steady
    t63 = None
    for k in range(n):
        if abs(rate[k]) >= abs(target):
            prev_t, prev_r = (0.0, 0.0) if k == 0 else (ends[k - 1], rate[k - 1])
            t63 = float(prev_t + (target - prev_r) / (rate[k] - prev_r) * (ends[k] - prev_t))
            break
    return {'primitive': primitive, 'period': period, 'period_end': ends.tolist(),
            'per_period_yaw_rate': rate.tolist(), 'steady_yaw_rate': steady, 't63': t63}


def coasting(sim: FrogSimulation, speed: float = 0.025, duration: float = 60.0) -> dict:
    """Glide from ``speed`` forward with no kick: speed after 5/20 s, distance, time to 5 mm/s."""
    sim.reset()
    sim.set_schedule(ActivationSchedule.empty())
    sim.set_velocity(speed, 0.0, 0.0)
    traj = sim.run(duration, record_interval=0.05)
    v = np.hypot(*traj.com_velocity.T)
    slow = np.nonzero(v < 0.005)[0]
    return {'start_speed': speed, 'speed_at_5s': float(np.interp(5.0, traj.time, v)),
            'speed_at_20s': float(np.interp(20.0, traj.time, v)),
            'distance': float(np.hypot(*(traj.com[-1] - traj.com[0]))), 'duration': duration,
            'time_to_5mm_s': float(traj.time[slow[0]]) if slow.size else None}


# ------------------------------------------------------------------ speeds
def read_experiment_speeds(path: Path | str | None = None) -> list[tuple[float, float, float, float]]:
    """Rows ``(egain %, frequency Hz, phase, speed m/s)`` of ``experiment_speeds.csv``."""
    path = Path(path) if path else find_data_file(EXPERIMENT_SPEEDS_FILE)
    with open(path, newline='') as fh:
        return [(float(r['egain_vol_pct']), float(r['frequency_hz']), float(r['phase_offset']),
                 float(r['speed_m_per_s'])) for r in csv.DictReader(fh)]


def steady_speed(params: FrogParameters, egain: float, frequency: float, library, time_step=DEFAULT_TIME_STEP,
                 cycles: int = 8, skip: int = 3, phase: float = 0.5) -> float:
    """Steady gait speed [m/s] (slope after ``skip`` cycles), or NaN if no profile exists."""
    try:
        library.profile(egain, frequency)
    except ValueError:
        return float('nan')
    sim = FrogSimulation(params.replace(egain_vol_pct=egain), time_step=time_step, library=library)
    sim.set_gait(frequency, phase)
    traj = sim.run(cycles / frequency, record_interval=0.01)
    return traj.forward_speed(skip / frequency)


def speed_comparison(params: FrogParameters, library, time_step=DEFAULT_TIME_STEP, progress=None) -> dict:
    """Simulated vs measured speeds: calibration runs, every experiment, best designs."""
    from .studies import measured_speeds
    from .sweeps import SmaPulseEnergy, robot_mass
    cal = measured_speeds()
    cal_rows = []
    for f in sorted(cal):
        m = float(np.nanmean(list(cal[f].values())))
        cal_rows.append({'egain_vol_pct': 10.0, 'frequency_hz': f, 'measured': m,
                         'simulated': steady_speed(params, 10.0, f, library, time_step)})
        if progress:
            progress()
    exp_rows = []
    cache = {(r['egain_vol_pct'], r['frequency_hz']): r['simulated'] for r in cal_rows}
    for e, f, _, v in read_experiment_speeds():
        key = (e, round(f, 1))
        if key not in cache:
            cache[key] = steady_speed(params, e, f, library, time_step)
            if progress:
                progress()
        exp_rows.append({'egain_vol_pct': e, 'frequency_hz': f, 'measured': v, 'simulated': cache[key]})
    # the simulated design grid at phase 0.5 (every measured profile)
    energy = SmaPulseEnergy()
    grid = []
    for (e, f) in sorted(library.profiles):
        key = (e, round(f, 1))
        if key not in cache:
            cache[key] = steady_speed(params, e, f, library, time_step)
            if progress:
                progress()
        mass = robot_mass(params.replace(egain_vol_pct=e))
        grid.append({'egain_vol_pct': e, 'frequency_hz': f, 'speed': cache[key],
                     'cost_of_transport': energy.cost_of_transport(f, mass, cache[key])})

    def rms(rows):
        err = np.array([r['simulated'] - r['measured'] for r in rows if np.isfinite(r['simulated'])])
        return float(np.sqrt(np.mean(err ** 2))) if err.size else float('nan')
    fastest = sorted(grid, key=lambda r: -r['speed'])[:2]
    efficient = sorted(grid, key=lambda r: r['cost_of_transport'])[:2]
    skipped = [(r['egain_vol_pct'], r['frequency_hz']) for r in exp_rows if not np.isfinite(r['simulated'])]
    return {'calibration': cal_rows, 'calibration_rms': rms(cal_rows), 'experiments': exp_rows,
            'experiments_rms': rms(exp_rows), 'experiments_not_simulated': skipped,
            'fastest': fastest, 'most_efficient': efficient,
            'fastest_as_paper': {(r['egain_vol_pct'], r['frequency_hz']) for r in fastest} <= PAPER_FASTEST,
            'most_efficient_as_paper': ({(r['egain_vol_pct'], r['frequency_hz']) for r in efficient}
                                        <= PAPER_MOST_EFFICIENT)}


# ------------------------------------------------------------------ report
def _side(tr) -> float:
    """+1 for F (turns left), -1 for E: mirrors single-side kicks onto one sign."""
    return 1.0 if tr.primitive == 'F' else -1.0


def _stats(values) -> dict:
    a = np.asarray(values, dtype=float)
    return {'mean': float(a.mean()) if a.size else float('nan'),
            'sd': float(a.std(ddof=1)) if a.size > 1 else float('nan'), 'n': int(a.size)}


def _mean_curve(trs, grid):
    rows = []
    for tr in trs:
        c = tr.extra.get('curve')
        if c is None:
            continue
        rows.append(_side(tr) * np.interp(grid, c['tau'], np.asarray(c['dheading'], dtype=float),
                                          left=np.nan, right=np.nan))
    a = np.array(rows)
    return np.nanmean(a, axis=0), np.nanstd(a, axis=0), len(rows)


def _peak_and_left(trs):
    peaks, left = [], []
    for tr in trs:
        c = tr.extra.get('curve')
        if c is None:
            continue
        r = _side(tr) * np.asarray(c['yaw_rate'], dtype=float)
        if np.all(np.isnan(r)):
            continue
        p = float(np.nanmax(r))
        peaks.append(p)
        if 'yaw_rate_next' in tr.extra and p > 0:
            left.append(_side(tr) * tr.extra['yaw_rate_next'] / p)
    return _stats(peaks), _stats(left)


@dataclass
class FidelityReport:
    """Everything ``frog-sim fidelity`` prints, plots and writes (SI; angles in rad)."""

    params: dict
    config: dict
    data: dict
    primitives: dict
    summary: dict
    curves: dict
    kick_from_rest: dict
    repeated: dict
    coasting: dict
    speeds: dict | None
    pairs: list = field(default_factory=list)
    replays: dict | None = None

    def to_json(self) -> str:
        def conv(o):
            if isinstance(o, set):
                return sorted(o)
            if isinstance(o, (np.floating, np.integer)):
                return o.item()
            if isinstance(o, np.ndarray):
                return o.tolist()
            raise TypeError(type(o))
        return json.dumps(asdict(self), indent=1, default=conv)


def fidelity_report(params: FrogParameters | None = None, config: FidelityConfig | None = None,
                    library: ActuationLibrary | None = None, real=None, progress=None) -> FidelityReport:
    """Compare the simulator with the hardware runs and the speed experiments.

    Parameters
    ----------
    params : FrogParameters, optional
        Model to test (default: today's defaults).
    real : tuple, optional
        ``real_transitions(...)`` result to reuse (it does not depend on the model).
    progress : callable, optional
        Called once per simulation.
    """
    params = params or FrogParameters()
    config = config or FidelityConfig()
    library = library or ActuationLibrary.load()
    if real is None:
        folder = find_data_file(f'hardware_runs/{config.runs[0]}.csv').parent
        real = real_transitions(folder, config.runs, config.tag_offset_deg)
    trs, info = real
    sim = FrogSimulation(params, time_step=config.time_step, library=library)
    replays = None
    if config.replay_periods > 0:
        from . import multi_period as mp
        folder = find_data_file(f'hardware_runs/{config.runs[0]}.csv').parent
        logs = hr.read_hardware_runs(folder, config.runs)
        windows = mp.real_windows(logs, info['tag_offset_rad'], config.replay_periods, curves=True)
        replays = mp.replay_report(sim, windows, config.latency, config.replay_periods, progress)
    pairs = []
    for tr in trs:
        pairs.append((tr, simulate_transition(sim, tr, config.latency, curve=tr.primitive in ('E', 'F'))))
        if progress:
            progress()
    prim = {}
    for p in sorted({tr.primitive for tr in trs}):
        sel = [(a, b) for a, b in pairs if a.primitive == p]
        row = {}
        for q in ('dx', 'dy', 'dheading'):
            ra = _stats([getattr(a, q) for a, _ in sel])
            sa = _stats([getattr(b, q) for _, b in sel])
            row[q] = {'real': ra, 'sim': sa, 'ratio': sa['mean'] / ra['mean'] if ra['mean'] else float('nan')}
        prim[p] = row
    turning = [(a, b) for a, b in pairs if a.primitive in TURNING]
    ef = [(a, b) for a, b in pairs if a.primitive in ('E', 'F')]
    grid = np.arange(0.0, 1.40, 0.05)
    real_mean, real_sd, n_curves = _mean_curve([a for a, _ in ef], grid)
    sim_mean, sim_sd, _ = _mean_curve([b for _, b in ef], grid)
    real_peak, real_left = _peak_and_left([a for a, _ in ef])
    sim_peak, sim_left = _peak_and_left([b for _, b in ef])
    period = float(np.median([tr.period for tr in trs]))
    kick = kick_from_rest(sim, 'E')
    rep = repeated_kicks(sim, 'E', period=period, n=config.repeat_periods)
    same = [(a, b) for a, b in ef if a.previous == a.primitive]
    coast = coasting(sim, config.coast_speed, config.coast_duration)
    summary = {
        'turning_abs_dheading': {'real': _stats([abs(a.dheading) for a, _ in turning]),
                                 'sim': _stats([abs(b.dheading) for _, b in turning])},
        'turning_signed_ratio': _stats([b.dheading / a.dheading for a, b in turning if abs(a.dheading) > 0.02]),
        'ef_peak_yaw_rate': {'real': real_peak, 'sim': sim_peak},
        'ef_yaw_rate_left_at_next_decision': {'real': real_left, 'sim': sim_left},
        'ef_repeated_yaw_rate': {'real': _stats([_side(a) * a.dheading / a.period for a, _ in same]),
                                 'sim': _stats([_side(b) * b.dheading / b.period for _, b in same])},
    }
    curves = {'tau': grid.tolist(), 'real_mean': real_mean.tolist(), 'real_sd': real_sd.tolist(),
              'sim_mean': sim_mean.tolist(), 'sim_sd': sim_sd.tolist(), 'n': n_curves}
    speeds = speed_comparison(params, library, config.time_step, progress) if config.speeds else None
    return FidelityReport(params=params.as_dict(), config=asdict(config), data=info, primitives=prim,
                          summary=summary, curves=curves, kick_from_rest=kick, repeated=rep, coasting=coast,
                          speeds=speeds,
                          pairs=[{'real': a.as_dict(), 'sim': b.as_dict()} for a, b in pairs], replays=replays)


# ------------------------------------------------------------------ targets and table
def targets(rep: FidelityReport) -> list[tuple[str, str, bool | None]]:
    """The targets: ``(name, value text, met)`` (None: not measured)."""
    out = []
    for p in 'CDEF':
        row = rep.primitives.get(p)
        if row:
            r = row['dheading']['ratio']
            out.append((f'{p} heading change within +-25 %', f'ratio {r:.2f}', bool(0.75 <= r <= 1.25)))
    for p in 'EF':
        row = rep.primitives.get(p)
        if row:
            r = row['dy']['ratio']
            out.append((f'{p} sideways: right sign, within +-35 %', f'ratio {r:.2f}', bool(0.65 <= r <= 1.35)))
    if rep.replays:
        m = rep.replays['pooled']
        for group, gm in rep.replays.get('groups', {}).items():
            for n in range(1, 5):
                if n in gm:
                    r = gm[n]['heading_ratio']
                    out.append((f'{group}: {n}-period replays: heading ratio sim/real within 0.85-1.15', f'{r:.2f}',
                                bool(0.85 <= r <= 1.15)))
        if 3 in m:
            e = np.degrees(m[3]['rms_heading_error'])
            out.append(('3-period replays: RMS heading error <= 8 deg', f'{e:.1f} deg', bool(e <= 8.0)))
    r = rep.repeated['steady_yaw_rate']
    out.append(('E every period from rest: steady yaw rate 13.5 deg/s +-25 %', f'{abs(np.degrees(r)):.1f} deg/s',
                bool(abs(abs(np.degrees(r)) - 13.5) <= 0.25 * 13.5)))
    k = rep.kick_from_rest
    out.append(('yaw rate 1.5 s after one kick from rest <= 30 % of peak', f'{100 * k["ratio_at_1p5s"]:.0f} %',
                bool(abs(k['ratio_at_1p5s']) <= 0.30)))
    b = rep.primitives.get('B')
    if b:
        r = b['dx']['ratio']
        out.append(('B forward distance per period within +-15 %', f'ratio {r:.2f}', bool(0.85 <= r <= 1.15)))
    if rep.speeds:
        s = rep.speeds
        out.append(('speed RMS vs 10 % calibration runs <= 5 mm/s', f'{1e3 * s["calibration_rms"]:.1f} mm/s',
                    bool(s['calibration_rms'] <= 0.005)))
        out.append(('speed RMS vs all experiment speeds <= 8 mm/s', f'{1e3 * s["experiments_rms"]:.1f} mm/s '
                    f'({len(s["experiments"]) - len(s["experiments_not_simulated"])}/{len(s["experiments"])} '
                    'simulated)', bool(s['experiments_rms'] <= 0.008)))
        fast = ', '.join(f'{r["egain_vol_pct"]:g} % {r["frequency_hz"]:g} Hz' for r in s['fastest'])
        eff = ', '.join(f'{r["egain_vol_pct"]:g} % {r["frequency_hz"]:g} Hz' for r in s['most_efficient'])
        out.append(('fastest designs as the paper (30 % 1.3/1.4 Hz)', fast, bool(s['fastest_as_paper'])))
        out.append(('most efficient as the paper (10 % 0.4/0.5 Hz)', eff, bool(s['most_efficient_as_paper'])))
    return out


def format_table(rep: FidelityReport) -> str:
    """The report as text (mm, deg, mm/s)."""
    lines = ['per primitive (one period, start body frame; real vs simulated, mean +- sd):',
             f'{"prim":>4} {"n":>3} | {"dx real":>12} {"dx sim":>12} {"ratio":>5} | {"dy real":>12} '
             f'{"dy sim":>12} {"ratio":>5} | {"dh real":>12} {"dh sim":>12} {"ratio":>5}']
    for p, row in rep.primitives.items():
        cells = []
        for q, scale in (('dx', 1e3), ('dy', 1e3), ('dheading', np.degrees(1.0))):
            r, s = row[q]['real'], row[q]['sim']
            cells.append(f'{scale * r["mean"]:6.1f}+-{scale * r["sd"]:4.1f} {scale * s["mean"]:6.1f}+-'
                         f'{scale * s["sd"]:4.1f} {row[q]["ratio"]:5.2f}'.replace('nan', '  - '))
        lines.append(f'{p:>4} {row["dx"]["real"]["n"]:3d} | ' + ' | '.join(cells))
    lines.append('  (dx, dy [mm], dh [deg])')
    s = rep.summary
    deg = np.degrees(1.0)
    ta = s['turning_abs_dheading']
    lines += ['', 'turning and yaw:',
              f'  |heading change| per period, C-H (n={ta["real"]["n"]}): real {deg * ta["real"]["mean"]:.1f} deg, '
              f'sim {deg * ta["sim"]["mean"]:.1f} deg (ratio {ta["sim"]["mean"] / ta["real"]["mean"]:.2f})',
              f'  E/F peak yaw rate (local fits): real {deg * s["ef_peak_yaw_rate"]["real"]["mean"]:.1f} deg/s, '
              f'sim {deg * s["ef_peak_yaw_rate"]["sim"]["mean"]:.1f} deg/s',
              f'  E/F yaw rate left at the next decision / peak: real '
              f'{100 * s["ef_yaw_rate_left_at_next_decision"]["real"]["mean"]:.0f} %, sim '
              f'{100 * s["ef_yaw_rate_left_at_next_decision"]["sim"]["mean"]:.0f} %',
              f'  E/F after the same primitive, yaw rate over the period (n={s["ef_repeated_yaw_rate"]["real"]["n"]}): '
              f'real {deg * s["ef_repeated_yaw_rate"]["real"]["mean"]:.1f} deg/s, '
              f'sim {deg * s["ef_repeated_yaw_rate"]["sim"]["mean"]:.1f} deg/s']
    k = rep.kick_from_rest
    lines.append(f'  single E kick from rest (sim): peak {deg * k["peak_yaw_rate"]:.1f} deg/s at '
                 f'{k["peak_time"]:.2f} s, {100 * k["ratio_at_1p5s"]:.0f} % of it left at 1.5 s, '
                 f'total turn {deg * k["heading_change_total"]:.1f} deg')
    r = rep.repeated
    t63 = f'{r["t63"]:.1f} s' if r['t63'] is not None else 'not reached'
    lines.append(f'  E every {r["period"]:.2f} s from rest (sim): steady {deg * r["steady_yaw_rate"]:.1f} deg/s, '
                 f'63 % after {t63} (real: 13.5 deg/s, 2.3 s)')
    c = rep.coasting
    t5 = f'{c["time_to_5mm_s"]:.1f} s' if c['time_to_5mm_s'] is not None else f'> {c["duration"]:.0f} s'
    lines.append(f'  coasting from {1e3 * c["start_speed"]:.0f} mm/s (sim): {1e3 * c["speed_at_5s"]:.1f} mm/s '
                 f'after 5 s, {1e3 * c["speed_at_20s"]:.1f} after 20 s, below 5 mm/s after {t5}, '
                 f'{1e3 * c["distance"]:.0f} mm in {c["duration"]:.0f} s')
    if rep.speeds:
        sp = rep.speeds
        lines += ['', 'speeds (phase 0.5) [mm/s]:']
        lines.append('  10 % calibration runs: ' + ', '.join(
            f'{r["frequency_hz"]:g} Hz {1e3 * r["measured"]:.1f}/{1e3 * r["simulated"]:.1f}' for r in sp['calibration'])
            + f'  (measured/sim) RMS {1e3 * sp["calibration_rms"]:.1f}')
        lines.append(f'  all experiment speeds: RMS {1e3 * sp["experiments_rms"]:.1f} mm/s over '
                     f'{len(sp["experiments"]) - len(sp["experiments_not_simulated"])} of {len(sp["experiments"])}'
                     + (f' (no profile: {sp["experiments_not_simulated"]})' if sp['experiments_not_simulated'] else ''))
        for e in sorted({r['egain_vol_pct'] for r in sp['experiments']}):
            rows = [r for r in sp['experiments'] if r['egain_vol_pct'] == e]
            lines.append(f'    {e:g} %: ' + ', '.join(
                f'{r["frequency_hz"]:g} {1e3 * r["measured"]:.0f}/{1e3 * r["simulated"]:.0f}' for r in rows))
    if rep.replays:
        from .multi_period import format_replay_table
        lines += ['', format_replay_table(rep.replays)]
    lines += ['', 'targets:']
    for name, val, ok in targets(rep):
        lines.append(f'  [{"ok" if ok else "--"}] {name}: {val}')
    return '\n'.join(lines)


def plot_report(rep: FidelityReport, out: Path) -> list[Path]:
    """PNGs: real vs simulated per primitive; kick response curves; speeds."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    out = Path(out)
    files = []
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.8))
    colors = dict(zip(PRIMITIVE_NAMES, plt.get_cmap('tab10').colors))
    for ax, (q, scale, unit) in zip(axes, (('dx', 1e3, 'mm'), ('dy', 1e3, 'mm'), ('dheading', np.degrees(1.0), 'deg'))):
        lim = 0.0
        for p in sorted({pr['real']['primitive'] for pr in rep.pairs}):
            pts = np.array([[pr['real'][q], pr['sim'][q]] for pr in rep.pairs if pr['real']['primitive'] == p]) * scale
            ax.plot(pts[:, 0], pts[:, 1], 'o', ms=4, color=colors[p], label=p)
            lim = max(lim, np.abs(pts).max())
        ax.plot([-lim, lim], [-lim, lim], 'k--', lw=0.8)
        ax.set_xlabel(f'real {q} [{unit}]')
        ax.set_ylabel(f'simulated {q} [{unit}]')
        ax.set_aspect('equal')
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8, ncol=2)
    fig.suptitle('one decision period, start body frame: real robot vs simulator (same start velocity)')
    fig.tight_layout()
    files.append(out / 'transitions_scatter.png')
    fig.savefig(files[-1], dpi=110)
    plt.close(fig)

    fig, axes = plt.subplots(1, 3, figsize=(15, 4.5))
    c = rep.curves
    tau = np.array(c['tau'])
    deg = np.degrees(1.0)
    for key, color, label in (('real', 'k', f'real (mean of {c["n"]} E/F kicks)'), ('sim', 'C1', 'simulated')):
        m, s = deg * np.array(c[f'{key}_mean']), deg * np.array(c[f'{key}_sd'])
        axes[0].plot(tau, m, color=color, label=label)
        axes[0].fill_between(tau, m - s, m + s, color=color, alpha=0.15)
    axes[0].set_xlabel('time after the decision [s]')
    axes[0].set_ylabel('heading change toward the kick side [deg]')
    axes[0].set_title('single-side kicks (E mirrored onto F)')
    axes[0].legend(fontsize=8)
    k = rep.kick_from_rest
    axes[1].plot(k['tau'], deg * np.array(k['yaw_rate']), 'C1')
    axes[1].axvline(1.5, color='k', lw=0.6, ls=':')
    axes[1].set_xlabel('time after firing [s]')
    axes[1].set_ylabel('yaw rate [deg/s]')
    axes[1].set_title(f'one E kick from rest (sim): {100 * k["ratio_at_1p5s"]:.0f} % left at 1.5 s')
    r = rep.repeated
    axes[2].step(r['period_end'], deg * np.array(r['per_period_yaw_rate']), where='pre', color='C1', label='simulated')
    axes[2].axhline(-13.5, color='k', ls='--', lw=0.8, label='real: 13.5 deg/s, 63 % at 2.3 s')
    axes[2].set_xlabel('time [s]')
    axes[2].set_ylabel('mean yaw rate over each period [deg/s]')
    axes[2].set_title('E every period from rest')
    axes[2].legend(fontsize=8)
    for ax in axes:
        ax.grid(alpha=0.3)
    fig.tight_layout()
    files.append(out / 'kick_response.png')
    fig.savefig(files[-1], dpi=110)
    plt.close(fig)

    if rep.speeds:
        fig, ax = plt.subplots(figsize=(7, 4.5))
        rows = rep.speeds['experiments']
        for i, e in enumerate(sorted({r['egain_vol_pct'] for r in rows})):
            sel = [r for r in rows if r['egain_vol_pct'] == e]
            f = [r['frequency_hz'] for r in sel]
            ax.plot(f, [1e3 * r['measured'] for r in sel], '*', color=f'C{i}', ms=8, label=f'{e:g} % measured')
            ax.plot(f, [1e3 * r['simulated'] for r in sel], 'o-', color=f'C{i}', ms=4, lw=0.8, label=f'{e:g} % sim')
        ax.set_xlabel('frequency [Hz]')
        ax.set_ylabel('steady forward speed [mm/s]')
        ax.set_title(f'phase 0.5; RMS {1e3 * rep.speeds["experiments_rms"]:.1f} mm/s')
        ax.legend(fontsize=7, ncol=2)
        ax.grid(alpha=0.3)
        fig.tight_layout()
        files.append(out / 'speeds.png')
        fig.savefig(files[-1], dpi=110)
        plt.close(fig)
    if rep.replays:
        from .multi_period import plot_replays
        files += plot_replays(rep.replays, out)
    return files
