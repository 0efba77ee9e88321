"""Longer studies on the frog simulator (not unit tests): validation against the
calibration runs and time-step / edge-length convergence. Used by ``frog-sim``.

Results are returned as plain rows; the CLI prints them and writes them under a run
folder (``runs/`` is git-ignored).
"""
from __future__ import annotations

import csv
from dataclasses import dataclass

import numpy as np

from .core.actuation import CALIBRATION_FILE_NAME, ActuationLibrary, find_data_file
from .core.model_parameters import FrogParameters
from .core.simulation import DEFAULT_TIME_STEP, FrogSimulation


def measured_speeds(skip_cycles: float = 2.0) -> dict:
    """Steady forward speed [m/s] of every calibration run (10 % EGaIn, phase 0.5).

    The speed is the slope of a line fitted to distance vs time; for the ``long``
    recordings the first ``skip_cycles`` cycles are skipped, the ``three_cycles``
    recordings are already steady (README of the data).

    Returns
    -------
    dict
        ``{frequency_hz: {'long': v, 'three_cycles': v}}``.
    """
    rows: dict = {}
    with open(find_data_file(CALIBRATION_FILE_NAME), newline='') as fh:
        for r in csv.DictReader(fh):
            key = (round(float(r['frequency_hz']), 1), r['recording'])
            rows.setdefault(key, []).append((float(r['t_s']), float(r['forward_distance_m'])))
    out: dict = {}
    for (f, rec), vals in sorted(rows.items()):
        a = np.array(sorted(vals))
        start = a[0, 0] + (skip_cycles / f if rec == 'long' else 0.0)
        sel = a[:, 0] >= start
        if sel.sum() < 3:
            sel = np.ones(len(a), dtype=bool)
        out.setdefault(f, {})[rec] = float(np.polyfit(a[sel, 0], a[sel, 1], 1)[0])
    return out


@dataclass
class SpeedRow:
    """One line of the speed-vs-frequency comparison [m/s]."""

    frequency_hz: float
    measured_long: float
    measured_three_cycles: float
    simulated: float

    @property
    def measured(self) -> float:
        """Mean of the available measurements."""
        vals = [v for v in (self.measured_long, self.measured_three_cycles) if np.isfinite(v)]
        return float(np.mean(vals))


def simulated_speed(frequency_hz: float, phase_offset: float = 0.5, cycles: int = 8,
                    skip_cycles: int = 3, params: FrogParameters | None = None,
                    time_step: float = DEFAULT_TIME_STEP, library=None) -> float:
    """Steady forward speed [m/s] of the simulated gait (slope after ``skip_cycles``)."""
    sim = FrogSimulation(params, time_step=time_step, library=library)
    sim.set_gait(frequency_hz, phase_offset)
    traj = sim.run(cycles / frequency_hz, record_interval=max(time_step, 0.01))
    return traj.forward_speed(skip_cycles / frequency_hz)


def speed_validation(frequencies=(0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0, 1.1), params=None,
                     time_step: float = DEFAULT_TIME_STEP, progress=None) -> tuple[list, float]:
    """Simulated vs measured steady speed for 10 % EGaIn, phase 0.5 (paper Fig. 4a).

    Returns
    -------
    rows : list of SpeedRow
    rms : float
        RMS of (simulated - measured) over the frequencies [m/s] (paper's calibration cost).
    """
    params = (params or FrogParameters()).replace(egain_vol_pct=10.0)
    meas = measured_speeds()
    lib = ActuationLibrary.load()
    rows = []
    for f in frequencies:
        v_sim = simulated_speed(f, params=params, time_step=time_step, library=lib)
        m = meas.get(round(f, 1), {})
        rows.append(SpeedRow(f, m.get('long', np.nan), m.get('three_cycles', np.nan), v_sim))
        if progress:
            progress(rows[-1])
    err = np.array([r.simulated - r.measured for r in rows])
    return rows, float(np.sqrt(np.mean(err ** 2)))


def displacement_after_cycles(frequency_hz: float, cycles: int, time_step: float,
                              params: FrogParameters | None = None, library=None) -> float:
    """Forward COM displacement [m] after ``cycles`` gait cycles (phase 0.5)."""
    sim = FrogSimulation(params, time_step=time_step, library=library)
    sim.set_gait(frequency_hz, 0.5)
    sim.step(int(round(cycles / frequency_hz / time_step)))
    return float(sim.rigid_body_state().com[0] - 0.0)


def convergence_study(time_steps=(8e-3, 4e-3, 2e-3, 1e-3, 5e-4), edges_per_side=(23, 46, 92),
                      frequency_hz: float = 1.0, cycles: int = 10, progress=None) -> dict:
    """Time-step and edge-length convergence of the 10-cycle displacement.

    Returns
    -------
    dict
        ``{'dt': [(dt, displacement, |change vs previous|)], 'dl': [(dl, displacement, change)]}``.
        For a first-order method the change should halve when dt halves.
    """
    lib = ActuationLibrary.load()
    out = {'dt': [], 'dl': []}
    prev = None
    for dt in time_steps:
        d = displacement_after_cycles(frequency_hz, cycles, dt, library=lib)
        out['dt'].append((dt, d, np.nan if prev is None else abs(d - prev)))
        prev = d
        if progress:
            progress('dt', out['dt'][-1])
    prev = None
    for n in edges_per_side:
        p = FrogParameters(body_edges_per_side=n)
        d = displacement_after_cycles(frequency_hz, cycles, 1e-3, params=p, library=lib)
        out['dl'].append((p.edge_length, d, np.nan if prev is None else abs(d - prev)))
        prev = d
        if progress:
            progress('dl', out['dl'][-1])
    return out
