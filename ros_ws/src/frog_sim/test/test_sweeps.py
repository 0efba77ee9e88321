"""Drag calibration and design sweep: energy model by hand, known-answer calibration."""

import math

import numpy as np
import pytest

from frog_sim.core.model_parameters import FrogParameters
from frog_sim.studies import simulated_speed
from frog_sim.sweeps import SmaPulseEnergy, calibrate_body_drag, robot_mass, sweep_grid


def test_energy_model_by_hand():
    e = SmaPulseEnergy(battery_voltage=11.1, wire_resistance=2.0, pulse=0.08)
    assert e.current == pytest.approx(5.55)
    assert e.energy_per_pulse == pytest.approx(11.1 * 5.55 * 0.08)          # 4.9284 J
    # 4 pulses per cycle at 0.4 Hz, 0.2 kg robot at 2.2 cm/s
    p = 4 * 4.9284 * 0.4
    assert e.input_power(0.4) == pytest.approx(p)
    assert e.cost_of_transport(0.4, 0.2, 0.022) == pytest.approx(p / (0.2 * 9.81 * 0.022))
    assert e.cost_of_transport(0.4, 0.2, 0.0) == math.inf


def test_mass_grows_with_egain():
    masses = [robot_mass(FrogParameters(egain_vol_pct=e)) for e in (0.0, 30.0, 50.0)]
    assert masses[0] < masses[1] < masses[2]


def test_grid_covers_every_measured_pair_and_phase():
    grid = sweep_grid()
    pairs = {(e, f) for e, f, _ in grid}
    assert len(pairs) == 48                      # the data README: 48 (EGaIn, frequency) pairs
    assert len(grid) == 48 * 10
    assert sorted({p for _, _, p in grid}) == pytest.approx(np.arange(0, 0.95, 0.1))


@pytest.mark.slow
def test_calibration_recovers_a_known_drag_coefficient(tmp_path):
    """Synthetic 'measurements' made with C_bn = 1.2 outside the grid code path."""
    truth, freqs = 1.2, [0.8, 1.0]
    params = FrogParameters(body_drag_normal=truth)
    measured = {f: simulated_speed(f, 0.5, cycles=4, skip_cycles=2, params=params)
                for f in freqs}
    res = calibrate_body_drag(candidates=[0.8, 1.2, 1.6], frequencies=freqs, measured=measured,
                              work_dir=tmp_path / "w", cycles=4, skip_cycles=2, workers=1,
                              progress=False)
    assert res.best == pytest.approx(truth)
    assert res.rms[res.best_index] < 1e-9
    # physics: more body drag, slower swimming, at every frequency
    assert np.all(np.diff(res.simulated, axis=0) < 0)
