"""Joint calibration on N-period replays, with leave-one-run-out cross-validation.

Objective
---------
As :mod:`frog_sim.calibration` (each term a squared error over its tolerance, 1 at the
edge of its target), but the hardware terms come from the open-loop replays of
:mod:`frog_sim.multi_period` over N = 1..4 periods instead of one period:

* ``ratio_<group>_N``: the heading ratio sim/real after N periods pooled over the runs of
  each group (:func:`~frog_sim.multi_period.run_group`: the ellipses, where the robot turns for many periods in a
  row, and the lines and sines), ``((r - 1) / 0.15)^2``;
* ``rms_heading_3``: the RMS heading error after 3 periods, ``(e / 8 deg)^2``;
* ``distance_4``: the distance covered in 4 periods, sim/real pooled, ``((d - 1) / 0.10)^2``
  (the speed along a path, whose closed-loop target is twin/real within 0.9-1.1);
* the single-period targets: C/D/E/F heading (+-25 %), E/F side-slip (+-35 %), B
  forward (+-15 %), from the N = 1 windows (per primitive, means);
* the yaw left 1.5 s after one kick from rest, ``(max(0, q - 0.3) / 0.3)^2``, and the
  steady yaw rate of E every period from rest, ``((w - 13.5) / 3.4 deg/s)^2``;
* the speeds: ``(RMS / 8 mm/s)^2`` over every experiment speed and ``(RMS / 5 mm/s)^2``
  over the 10 % calibration runs (phase 0.5).

The calibration chooses the evaluated point that meets the most targets (each term's target:
:meth:`ReplayObjective.targets`) and, among those, has the lowest cost: the objective is flat
along the trade-off between the friction and the linear damping, and a point a hair cheaper
that gives up a target it could keep is not the better model.

Every evaluation keeps the simulated end poses of every window, so the hardware terms
can be scored on any subset of runs afterwards: a **leave-one-run-out cross-validation**
picks, for each run, the evaluated point best on the other runs and scores it on the
held-out run; pooled, every run's windows simulated with the point chosen without it. The
speeds do not depend on the runs and enter every fold.
"""
from __future__ import annotations

import itertools
import json
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import multi_period as mp
from .multi_period import run_group
from .calibration import read_evaluations
from .core import hardware_runs as hr
from .core.actuation import ActuationLibrary
from .core.model_parameters import FrogParameters, parameter_range
from .core.simulation import DEFAULT_TIME_STEP, FrogSimulation

#: The free parameters and their grid: the waterline friction in yaw (what stops a turn within
#: the period), the linear yaw and surge damping (the surge: the speed along the path).
DEFAULT_GRID = {'waterline_friction': (0.003, 0.006, 0.009),
                'yaw_damping_linear': (0.0002, 0.000375),
                'surge_damping_linear': (0.0, 0.025, 0.05)}
#: The model before the waterline friction (the earlier calibration's values): "before".
PREVIOUS_MODEL = {'waterline_friction': 0.0, 'yaw_damping_linear': 0.000375, 'surge_damping_linear': 0.0483}
#: Folds of the cross-validation: every run held out once.
DEFAULT_FOLDS = tuple((run,) for run in hr.HARDWARE_RUNS)
N_RATIO = (1, 2, 3, 4)
REPEATED_TARGET = np.radians(13.5)
#: Tolerances of the terms (the targets' half-widths).
RATIO_TOLERANCE = 0.15
RMS_HEADING_3_TARGET = np.radians(8.0)
DISTANCE_TOLERANCE = 0.10


def distance_ratios(windows, n_max: int = max(N_RATIO)) -> dict:
    """Per N: the mean distance covered in N periods, sim over real (windows with ``sim`` filled)."""
    out = {}
    for n in range(1, n_max + 1):
        rows = [(w.real[n - 1], w.sim[n - 1]) for w in windows if w.periods >= n and len(w.sim) >= n]
        if rows:
            real = np.mean([np.hypot(a[0], a[1]) for a, _ in rows])
            sim = np.mean([np.hypot(b[0], b[1]) for _, b in rows])
            out[n] = float(sim / real) if real > 0 else float('nan')
    return out


@dataclass
class ReplayEvaluation:
    """One simulated parameter point: window end poses, kick, repetition, speeds."""

    values: dict
    windows: list              # per window: list of (dx, dy, dh) per period end
    kick_ratio: float
    repeated_yaw_rate: float
    speeds: dict = field(default_factory=dict)


def _simulate(args) -> ReplayEvaluation:
    values, base, windows, latency, time_step, speed_points, cycles = args
    from .fidelity import kick_from_rest, repeated_kicks, steady_speed
    params = base.replace(**values)
    library = ActuationLibrary.load()
    sim = FrogSimulation(params, time_step=time_step, library=library)
    ends = [mp.simulate_window(sim, w, latency) for w in windows]
    kick = kick_from_rest(sim, 'E', 2.0)['ratio_at_1p5s']
    rep = repeated_kicks(sim, 'E', float(np.median([w.period for w in windows])), 8)['steady_yaw_rate']
    speeds = {}
    skip = max(2, int(round(3 * cycles / 8)))
    for e, f in speed_points:
        speeds[f'{e:g}@{f:g}'] = steady_speed(params, e, f, library, time_step, cycles, skip)
    return ReplayEvaluation(dict(values), ends, float(kick), float(rep), speeds)


class ReplayObjective:
    """Evaluations of parameter points against the replay windows and the speeds."""

    def __init__(self, windows, calibration_speeds, experiment_speeds, base: FrogParameters | None = None,
                 latency: float = hr.DECISION_TO_FIRING_S, time_step: float = DEFAULT_TIME_STEP, speed_cycles: int = 8,
                 cache_file=None):
        self.windows = list(windows)
        self.calibration_speeds = [(10.0, round(f, 1), v) for f, v in calibration_speeds]
        self.experiment_speeds = [(e, round(f, 1), v) for e, f, v in experiment_speeds]
        self.base = base or FrogParameters()
        self.latency = latency
        self.time_step = time_step
        self.speed_cycles = speed_cycles
        self.points = sorted({(e, f) for e, f, _ in self.calibration_speeds + self.experiment_speeds})
        self.cache: dict[str, ReplayEvaluation] = {}
        self.cache_file = Path(cache_file) if cache_file else None
        if self.cache_file:
            for row in read_evaluations(self.cache_file):
                ev = ReplayEvaluation(**row)
                self.cache[self._key(ev.values)] = ev

    @staticmethod
    def _key(values: dict) -> str:
        return json.dumps({k: round(float(v), 7) for k, v in sorted(values.items())})

    def evaluate(self, points: list[dict], workers: int = 1, progress=None) -> list[ReplayEvaluation]:
        """Evaluate (or take from the cache) each point; ``workers`` processes."""
        todo = [p for p in points if self._key(p) not in self.cache]
        args = [(p, self.base, self.windows, self.latency, self.time_step, self.points, self.speed_cycles)
                for p in todo]
        results = []
        if workers > 1 and len(args) > 1:
            with ProcessPoolExecutor(workers) as pool:
                for ev in pool.map(_simulate, args):
                    results.append(ev)
                    self._store(ev)
                    if progress:
                        progress(ev)
        else:
            for a in args:
                ev = _simulate(a)
                results.append(ev)
                self._store(ev)
                if progress:
                    progress(ev)
        return [self.cache[self._key(p)] for p in points]

    def _store(self, ev: ReplayEvaluation) -> None:
        self.cache[self._key(ev.values)] = ev
        if self.cache_file:
            with open(self.cache_file, 'a') as fh:
                fh.write(json.dumps({'values': ev.values, 'windows': ev.windows, 'kick_ratio': ev.kick_ratio,
                                     'repeated_yaw_rate': ev.repeated_yaw_rate, 'speeds': ev.speeds}) + '\n')

    # -- scoring ------------------------------------------------------------------------
    def metrics(self, ev: ReplayEvaluation, runs=None) -> dict:
        """Replay metrics (per N) and single-period ratios over ``runs`` (default: all)."""
        wins = []
        for w, ends in zip(self.windows, ev.windows):
            if runs is None or w.run in runs:
                w2 = mp.ReplayWindow(**{**w.__dict__, 'sim': ends, 'curve': {}})
                wins.append(w2)
        out = {'replays': mp.window_metrics(wins, max(N_RATIO)), 'primitives': {},
               'groups': {g: mp.window_metrics([w for w in wins if run_group(w.run) == g], max(N_RATIO))
                          for g in sorted({run_group(w.run) for w in wins})},
               'distance': distance_ratios(wins)}
        for p in 'BCDEF':
            sel = [w for w in wins if w.primitives[0] == p]
            if sel:
                r = np.mean([w.real[0] for w in sel], axis=0)
                s = np.mean([w.sim[0] for w in sel], axis=0)
                out['primitives'][p] = {'dx': s[0] / r[0], 'dy': s[1] / r[1], 'dheading': s[2] / r[2], 'n': len(sel)}
        sp = ev.speeds

        def rms(rows):
            err = [sp[f'{e:g}@{f:g}'] - v for e, f, v in rows if np.isfinite(sp.get(f'{e:g}@{f:g}', np.nan))]
            return float(np.sqrt(np.mean(np.square(err)))) if err else float('nan')
        out['speed_rms_experiments'] = rms(self.experiment_speeds)
        out['speed_rms_calibration'] = rms(self.calibration_speeds)
        out['kick_ratio'] = ev.kick_ratio
        out['repeated_yaw_rate'] = ev.repeated_yaw_rate
        return out

    def terms(self, ev: ReplayEvaluation, runs=None) -> dict:
        """Squared errors over tolerances (module doc)."""
        m = self.metrics(ev, runs)
        t = {}
        for g, gm in m['groups'].items():
            for n in N_RATIO:
                if n in gm:
                    t[f'ratio_{g}_{n}'] = ((gm[n]['heading_ratio'] - 1.0) / RATIO_TOLERANCE) ** 2
        if 3 in m['replays']:
            t['rms_heading_3'] = (m['replays'][3]['rms_heading_error'] / RMS_HEADING_3_TARGET) ** 2
        if max(N_RATIO) in m['distance']:
            t[f'distance_{max(N_RATIO)}'] = ((m['distance'][max(N_RATIO)] - 1.0) / DISTANCE_TOLERANCE) ** 2
        prim = m['primitives']
        for p in 'CDEF':
            if p in prim:
                t[f'dheading_{p}'] = ((prim[p]['dheading'] - 1.0) / 0.25) ** 2
        for p in 'EF':
            if p in prim:
                t[f'dy_{p}'] = ((prim[p]['dy'] - 1.0) / 0.35) ** 2
        if 'B' in prim:
            t['dx_B'] = ((prim['B']['dx'] - 1.0) / 0.15) ** 2
        t['yaw_decay'] = (max(0.0, abs(m['kick_ratio']) - 0.3) / 0.3) ** 2
        t['repeated_E'] = ((abs(m['repeated_yaw_rate']) - REPEATED_TARGET) / (0.25 * REPEATED_TARGET)) ** 2
        if np.isfinite(m['speed_rms_experiments']):
            t['speed_experiments'] = (m['speed_rms_experiments'] / 0.008) ** 2
        if np.isfinite(m['speed_rms_calibration']):
            t['speed_calibration'] = (m['speed_rms_calibration'] / 0.005) ** 2
        return t

    def targets(self, ev: ReplayEvaluation, runs=None) -> dict:
        """Each target met or not over ``runs`` (name -> bool): the heading ratios per group and N
        within 0.85-1.15, the RMS heading error at 3 periods <= 8 deg, the C-F heading within 25 %,
        the E/F side-slip within 35 %, B forward and the distance in 4 periods within 15 % and 10 %,
        the yaw left after a kick <= 30 %, E repeated within 25 % of 13.5 deg/s, the speed RMS <= 8
        and <= 5 mm/s."""
        m = self.metrics(ev, runs)
        out = {}
        for g, gm in m['groups'].items():
            for n in N_RATIO:
                if n in gm:
                    out[f'ratio_{g}_{n}'] = abs(gm[n]['heading_ratio'] - 1.0) <= RATIO_TOLERANCE
        if 3 in m['replays']:
            out['rms_heading_3'] = m['replays'][3]['rms_heading_error'] <= RMS_HEADING_3_TARGET
        prim = m['primitives']
        checks = [(p, 'dheading', 0.25) for p in 'CDEF'] + [(p, 'dy', 0.35) for p in 'EF'] + [('B', 'dx', 0.15)]
        for p, q, tol in checks:
            if p in prim and np.isfinite(prim[p][q]):
                out[f'{q}_{p}'] = abs(prim[p][q] - 1.0) <= tol
        n = max(N_RATIO)
        if n in m['distance']:
            out[f'distance_{n}'] = abs(m['distance'][n] - 1.0) <= DISTANCE_TOLERANCE
        out['yaw_decay'] = abs(m['kick_ratio']) <= 0.3
        out['repeated_E'] = abs(abs(m['repeated_yaw_rate']) - REPEATED_TARGET) <= 0.25 * REPEATED_TARGET
        if np.isfinite(m['speed_rms_experiments']):
            out['speed_experiments'] = m['speed_rms_experiments'] <= 0.008
        if np.isfinite(m['speed_rms_calibration']):
            out['speed_calibration'] = m['speed_rms_calibration'] <= 0.005
        return out

    def rank_key(self, ev: ReplayEvaluation, runs=None) -> tuple:
        """Sort key of the calibration's choice: the most targets met, then the lowest cost."""
        return (-sum(self.targets(ev, runs).values()), self.cost(ev, runs))

    def cost(self, ev: ReplayEvaluation, runs=None) -> float:
        """Sum of the terms (a term the runs cannot score, NaN, is left out)."""
        return float(sum(v for v in self.terms(ev, runs).values() if np.isfinite(v)))


def grid_points(grid: dict) -> list[dict]:
    names = list(grid)
    return [dict(zip(names, combo)) for combo in itertools.product(*(grid[n] for n in names))]


def refine(objective: ReplayObjective, start: dict, scale: dict, runs=None, iterations: int = 12, progress=None):
    """Nelder-Mead from ``start`` (each parameter scaled by ``scale``, clipped to its range)."""
    from scipy.optimize import minimize
    names = list(start)
    s = np.array([scale[n] for n in names])
    bounds = [parameter_range(n) for n in names]
    x0 = np.array([start[n] for n in names]) / s
    seen = []

    def f(z):
        vals = {n: float(np.clip(v * sc, *b)) for n, v, sc, b in zip(names, z, s, bounds)}
        ev = objective.evaluate([vals], progress=progress)[0]
        seen.append(ev)
        return objective.cost(ev, runs)
    simplex = [x0] + [x0 + 0.5 * np.eye(len(names))[i] for i in range(len(names))]
    minimize(f, x0, method='Nelder-Mead', options={'maxfev': iterations, 'initial_simplex': np.array(simplex),
                                                   'xatol': 0.05, 'fatol': 0.02})
    return min(seen, key=lambda e: objective.cost(e, runs))


def cross_validate(objective: ReplayObjective, candidates, folds=None) -> list[dict]:
    """Per fold: the candidate best on the other runs (:meth:`ReplayObjective.rank_key`: the most
    targets met, then the lowest cost), its cost there and its metrics on the held-out runs
    (default folds: every run of the objective's windows held out once)."""
    runs = sorted({w.run for w in objective.windows})
    folds = folds or tuple((r,) for r in runs)
    out = []
    for held in folds:
        train = [r for r in runs if r not in held]
        best = min(candidates, key=lambda e: objective.rank_key(e, train))
        out.append({'held_out': list(held), 'train': train, 'chosen': best.values,
                    'train_cost': objective.cost(best, train), 'held_out_cost': objective.cost(best, held),
                    'held_out_terms': objective.terms(best, held),
                    'held_out_metrics': _jsonable(objective.metrics(best, held))})
    return out


def held_out_windows(objective: ReplayObjective, candidates, cv: list[dict]) -> list:
    """Every window of the held-out runs, simulated with its fold's choice (the pooled
    cross-validation: no run's windows scored by parameters chosen with them)."""
    by_key = {objective._key(e.values): e for e in candidates}
    out = []
    for fold in cv:
        ev = by_key[objective._key(fold['chosen'])]
        for w, ends in zip(objective.windows, ev.windows):
            if w.run in fold['held_out']:
                out.append(mp.ReplayWindow(**{**w.__dict__, 'sim': ends, 'curve': {}}))
    return out


def held_out_summary(windows) -> dict:
    """Metrics of :func:`held_out_windows`: per N, pooled, per group and per run."""
    n_max = max(N_RATIO)
    return {'pooled': mp.window_metrics(windows, n_max),
            'groups': {g: mp.window_metrics([w for w in windows if run_group(w.run) == g], n_max)
                       for g in sorted({run_group(w.run) for w in windows})},
            'per_run': {r: mp.window_metrics([w for w in windows if w.run == r], n_max)
                        for r in sorted({w.run for w in windows})},
            'distance': distance_ratios(windows)}


def _jsonable(o):
    if isinstance(o, dict):
        return {str(k): _jsonable(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_jsonable(v) for v in o]
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    return o
