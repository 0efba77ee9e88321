"""Joint calibration of the few free model parameters.

Objective
---------
Every issue target becomes one term, a squared error divided by its tolerance, so a
term is 1 exactly at the edge of its target and the sum says how many tolerances the
model is off in total:

* turning: the mean heading change per period of C, D, E and F, ``((sim - real) / real / 0.25)^2``;
* side-slip: the mean sideways displacement of E and F, ``(... / 0.35)^2``;
* B: the mean forward distance per period, ``(... / 0.15)^2``;
* yaw decay: the yaw rate left 1.5 s after a single kick from rest, ``(max(0, q - 0.3) / 0.3)^2``;
* speeds: ``(RMS / 5 mm/s)^2`` against the 10 % calibration runs and ``(RMS / 8 mm/s)^2``
  against every experiment speed (phase 0.5).

The transitions enter through each primitive's *mean* real start state (velocity) and
mean real transition, so one evaluation costs one simulation per primitive; the speeds
cost one gait per design. The full per-decision comparison (``frog-sim fidelity``) is
run on the result.

Search
------
Coarse-to-fine, few free parameters: (1) a grid over the kick's geometry -- the sense of
the relaxed curl (Fig. 2b does not show it), limb fluid width, rear root angle, front
root offset -- scored on the transition and yaw terms only
(one simulation per primitive, ~0.5 s a point); (2) Nelder-Mead on the full objective
(with the speeds, ~10 s a point) from the best grid point, adding C_bn. Every evaluation
is cached (in memory and in ``<out>/evaluations.jsonl``, so a rerun resumes).

Cross-validation
----------------
Fit on the line runs and two sines (sin1, sin2); the held-out sines (sin3, sin4) are
reported separately with the same terms.
"""
from __future__ import annotations

import itertools
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .core.actuation import ActuationLibrary
from .core.hardware_runs import Transition
from .core.model_parameters import FrogParameters, parameter_range
from .core.simulation import DEFAULT_TIME_STEP, FrogSimulation

TURN_PRIMITIVES = ('C', 'D', 'E', 'F')
SLIP_PRIMITIVES = ('E', 'F')
#: The physics that the calibration starts from (docs/results.md, "Simulator fidelity").
PHYSICAL_BASE = {'body_fluid_section': 'height', 'added_mass_lumping': 'direction_average'}
#: The model before the joint calibration (4 mm body rod, 4 mm limbs, paper's lumping, one root angle).
LEGACY_MODEL = {'body_fluid_section': 'rod', 'added_mass_lumping': 'normal', 'limb_fluid_width': 0.004,
                'limb_root_angle_deg': -75.0, 'front_root_angle_offset_deg': 0.0, 'body_drag_normal': 0.8,
                'limb_curl_direction': 'backward'}
DEFAULT_FREE = ('limb_fluid_width', 'limb_root_angle_deg', 'front_root_angle_offset_deg', 'body_drag_normal')
#: Stage 1 (transitions and yaw decay only, ~0.5 s per point): the geometry of the kick.
DEFAULT_GRID = {
    'limb_curl_direction': ('backward', 'forward'),
    'limb_fluid_width': (0.010, 0.016, 0.022, 0.028),
    'limb_root_angle_deg': (-90.0, -75.0, -60.0, -45.0),
    'front_root_angle_offset_deg': (0.0, 30.0, 60.0, 90.0),
}
#: Stage 2 adds C_bn (start value: the paper's 0.8), which mainly the speeds determine.
DEFAULT_REFINE_START = {'body_drag_normal': 0.8}
TRAIN_RUNS = ('line1', 'line2', 'sin1', 'sin2')
TEST_RUNS = ('sin3', 'sin4')


@dataclass
class PrimitiveTarget:
    """Mean real start state and transition of one primitive (SI)."""

    primitive: str
    n: int
    period: float
    forward: float
    lateral: float
    yaw_rate: float
    dx: float
    dy: float
    dheading: float


def primitive_targets(transitions, primitives=('B', 'C', 'D', 'E', 'F')) -> dict:
    """``{primitive: PrimitiveTarget}`` from real transitions (means over decisions)."""
    out = {}
    for p in primitives:
        sel = [t for t in transitions if t.primitive == p]
        if not sel:
            continue
        a = np.array([[t.period, t.forward, t.lateral, t.yaw_rate, t.dx, t.dy, t.dheading] for t in sel])
        out[p] = PrimitiveTarget(p, len(sel), *[float(v) for v in a.mean(axis=0)])
    return out


def read_evaluations(path: Path) -> list[dict]:
    """Rows of an ``evaluations.jsonl`` cache (none if absent); a line cut by an interrupted
    run is skipped."""
    rows = []
    if path.is_file():
        for line in path.read_text().splitlines():
            try:
                rows.append(json.loads(line))
            except ValueError:
                continue
    return rows


@dataclass
class Evaluation:
    """One objective evaluation."""

    values: dict
    cost: float
    terms: dict
    sim: dict = field(default_factory=dict)


class JointObjective:
    """The calibration objective for a set of real transitions and speed points.

    Parameters
    ----------
    targets : dict
        :func:`primitive_targets` of the fitting runs.
    calibration_speeds : list of (frequency, speed)
        10 % runs [Hz, m/s].
    experiment_speeds : list of (egain, frequency, speed)
        [%, Hz, m/s].
    base : FrogParameters
        Everything not free.
    latency : float
        Decision -> firing [s] (as ``frog-sim fidelity``).
    """

    def __init__(self, targets: dict, calibration_speeds, experiment_speeds, base: FrogParameters,
                 latency: float = 0.10, time_step: float = DEFAULT_TIME_STEP, library=None, cache_file=None,
                 speeds: bool = True, speed_cycles: int = 8):
        self.targets = targets
        self.library = library or ActuationLibrary.load()
        self.speeds = speeds
        self.speed_cycles = int(speed_cycles)
        self.calibration_speeds = list(calibration_speeds)
        self.experiment_speeds = list(experiment_speeds)
        self.base = base
        self.latency = latency
        self.time_step = time_step
        self.cache: dict = {}
        # what the evaluations depend on besides the free values (targets, base model, settings)
        import hashlib
        ident = json.dumps({'targets': {p: vars(t) for p, t in sorted(targets.items())},
                            'base': base.as_dict(), 'latency': latency, 'dt': time_step,
                            'cal': self.calibration_speeds, 'exp': self.experiment_speeds,
                            'data': self.library.source.get('data_sha256')}, sort_keys=True, default=str)
        self.ident = hashlib.sha256(ident.encode()).hexdigest()[:16]
        self.cache_file = Path(cache_file) if cache_file else None
        if self.cache_file:
            for row in read_evaluations(self.cache_file):
                if row.get('key'):
                    self.cache[row['key']] = Evaluation(row['values'], row['cost'], row['terms'], row.get('sim', {}))

    def _key(self, values: dict) -> str:
        return json.dumps({'id': self.ident, 'speeds': self.speeds, 'cycles': self.speed_cycles,
                           **{k: (v if isinstance(v, str) else round(float(v), 6)) for k, v in sorted(values.items())}})

    def simulate(self, params: FrogParameters) -> dict:
        """Simulated counterparts: per-primitive transitions, kick decay, speeds."""
        from .fidelity import kick_from_rest, simulate_transition, steady_speed
        sim = FrogSimulation(params, time_step=self.time_step, library=self.library)
        out = {'transitions': {}}
        for p, t in self.targets.items():
            tr = Transition('mean', 0, 0.0, t.period, p, '', t.forward, t.lateral, t.yaw_rate, 0.0, 0.0, 0.0)
            s = simulate_transition(sim, tr, self.latency)
            out['transitions'][p] = {'dx': s.dx, 'dy': s.dy, 'dheading': s.dheading}
        out['kick_ratio_at_1p5s'] = kick_from_rest(sim, 'E', 2.0)['ratio_at_1p5s']
        if not self.speeds:
            return out
        n, skip = self.speed_cycles, max(2, int(round(3 * self.speed_cycles / 8)))
        speeds = {}
        for f, _ in self.calibration_speeds:
            speeds[(10.0, round(f, 1))] = steady_speed(params, 10.0, f, self.library, self.time_step, n, skip)
        for e, f, _ in self.experiment_speeds:
            key = (e, round(f, 1))
            if key not in speeds:
                speeds[key] = steady_speed(params, e, f, self.library, self.time_step, n, skip)
        out['speeds'] = {f'{e:g}@{f:g}': v for (e, f), v in speeds.items()}
        return out

    def terms(self, sim: dict) -> dict:
        """Squared errors over tolerances (see module doc)."""
        t = {}
        for p in TURN_PRIMITIVES:
            if p in self.targets:
                real = self.targets[p].dheading
                t[f'dheading_{p}'] = ((sim['transitions'][p]['dheading'] - real) / real / 0.25) ** 2
        for p in SLIP_PRIMITIVES:
            if p in self.targets:
                real = self.targets[p].dy
                t[f'dy_{p}'] = ((sim['transitions'][p]['dy'] - real) / real / 0.35) ** 2
        if 'B' in self.targets:
            real = self.targets['B'].dx
            t['dx_B'] = ((sim['transitions']['B']['dx'] - real) / real / 0.15) ** 2
        q = abs(sim['kick_ratio_at_1p5s'])
        t['yaw_decay'] = (max(0.0, q - 0.3) / 0.3) ** 2
        if 'speeds' not in sim:
            return t
        sp = sim['speeds']

        def rms(pairs):
            err = [sp[f'{e:g}@{round(f, 1):g}'] - v for e, f, v in pairs
                   if np.isfinite(sp[f'{e:g}@{round(f, 1):g}'])]
            return float(np.sqrt(np.mean(np.square(err)))) if err else float('nan')
        cal = rms([(10.0, f, v) for f, v in self.calibration_speeds])
        exp = rms(self.experiment_speeds)
        t['speed_calibration'] = (cal / 0.005) ** 2
        t['speed_experiments'] = (exp / 0.008) ** 2
        t['_rms_calibration_m_s'] = cal
        t['_rms_experiments_m_s'] = exp
        return t

    def __call__(self, values: dict) -> Evaluation:
        key = self._key(values)
        if key in self.cache:
            return self.cache[key]
        try:
            params = self.base.replace(**values)
        except ValueError:
            ev = Evaluation(dict(values), float('inf'), {'error': 'outside the parameter ranges'})
            self.cache[key] = ev
            return ev
        sim = self.simulate(params)
        terms = self.terms(sim)
        cost = float(sum(v for k, v in terms.items() if not k.startswith('_')))
        ev = Evaluation({k: (v if isinstance(v, str) else float(v)) for k, v in values.items()}, cost, terms, sim)
        self.cache[key] = ev
        if self.cache_file:
            with open(self.cache_file, 'a') as fh:
                fh.write(json.dumps({'key': key, 'values': ev.values, 'cost': ev.cost, 'terms': ev.terms,
                                     'sim': ev.sim}) + '\n')
        return ev


def coarse_to_fine(grid_objective: JointObjective, grid: dict, refine_objective: JointObjective | None = None,
                   refine: dict | None = None, refine_iterations: int = 30, progress=None):
    """Grid search with ``grid_objective``, then Nelder-Mead with ``refine_objective``.

    The grid is over ``grid`` (name -> values); the refinement starts from the best grid
    point plus the start values ``refine`` of further free parameters (e.g. C_bn, which
    only the speeds determine) and moves every parameter, each scaled by its grid spacing
    (or 10 % of its value) and clipped to its range.

    Returns
    -------
    best : Evaluation
        Best of the refinement (or of the grid without one).
    history : list of (stage, Evaluation)
    """
    from scipy.optimize import minimize
    names = list(grid)
    history = []
    for combo in itertools.product(*(grid[n] for n in names)):
        ev = grid_objective(dict(zip(names, combo)))
        history.append(('grid', ev))
        if progress:
            progress('grid', ev)
    best = min((ev for _, ev in history), key=lambda e: e.cost)
    if refine_objective is None or refine_iterations <= 0:
        return best, history
    start = {**best.values, **(refine or {})}
    fixed = {n: v for n, v in start.items() if isinstance(v, str)}   # choices stay at the grid's best
    names = [n for n in start if n not in fixed]
    scale = np.array([np.ptp(np.asarray(grid[n], dtype=float)) / max(len(grid[n]) - 1, 1)
                      if n in grid and len(grid[n]) > 1
                      else max(abs(start[n]) * 0.1, 1e-3) for n in names])
    bounds = [parameter_range(n) for n in names]
    x0 = np.array([start[n] for n in names]) / scale
    refined = []

    def f(z):
        vals = {**fixed, **{n: float(np.clip(v * s, *b)) for n, v, s, b in zip(names, z, scale, bounds)}}
        ev = refine_objective(vals)
        refined.append(ev)
        history.append(('refine', ev))
        if progress:
            progress('refine', ev)
        return ev.cost
    simplex = [x0] + [x0 + 0.5 * np.eye(len(names))[i] for i in range(len(names))]
    minimize(f, x0, method='Nelder-Mead', options={'maxfev': refine_iterations, 'initial_simplex': np.array(simplex),
                                                   'xatol': 0.05, 'fatol': 0.02})
    return min(refined, key=lambda e: e.cost), history


def read_targets(folder, runs, tag_offset_deg=None):
    """Real transitions of ``runs`` (hardware_runs folder) and their primitive targets."""
    from .fidelity import real_transitions
    trs, info = real_transitions(folder, runs, tag_offset_deg)
    return trs, primitive_targets(trs), info
