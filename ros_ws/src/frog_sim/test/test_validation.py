"""Against the authors' measurements and against refined discretisations."""

import numpy as np
import pytest

from frog_sim.core.model_parameters import FrogParameters
from frog_sim.studies import displacement_after_cycles, measured_speeds, speed_validation


@pytest.mark.slow
def test_steady_speed_matches_calibration_runs(measured_file):
    """10 % EGaIn, phase 0.5, 0.4-1.1 Hz vs the measured runs (paper: good agreement).
    Measured speeds rise from ~22 to ~56 mm/s; the model must follow within 5 mm/s RMS (the
    issue-11 target; the jointly calibrated model: ~3.6 mm/s here, 4.9 with 1.2 Hz) and
    rise with frequency like the measurements."""
    measured_file("calibration_runs_10pct.csv")
    rows, rms = speed_validation()
    sim = np.array([r.simulated for r in rows])
    meas = np.array([r.measured for r in rows])
    print("\n f [Hz]  measured [mm/s]  simulated [mm/s]")
    for r in rows:
        print(f"  {r.frequency_hz:.1f}   {1e3 * r.measured:8.1f}   {1e3 * r.simulated:8.1f}")
    print(f"RMS error {1e3 * rms:.1f} mm/s")
    assert rms < 0.005
    assert np.corrcoef(sim, meas)[0, 1] > 0.9
    assert np.all(np.abs(sim - meas) < 0.012)


def test_measured_speeds_read_from_the_data_file(measured_file):
    measured_file("calibration_runs_10pct.csv")
    m = measured_speeds()
    assert sorted(m) == pytest.approx([0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0, 1.1, 1.2])
    assert 0.018 < m[0.4]["long"] < 0.028 and 0.05 < m[1.1]["long"] < 0.06


@pytest.mark.slow
def test_time_step_refinement_converges():
    """Halving dt from 0.5 ms changes the 3-cycle displacement by shrinking amounts that
    approach first order (ratio of successive changes -> 1/2 for backward Euler). Above
    0.5 ms the dt-dependent numerical damping of the limbs' stiff bending modes spoils the
    asymptotic regime (see the report's convergence study)."""
    params = FrogParameters()
    d = [displacement_after_cycles(1.0, 3, dt, params) for dt in (5e-4, 2.5e-4, 1.25e-4, 6.25e-5)]
    changes = np.abs(np.diff(d))
    ratios = changes[1:] / changes[:-1]
    assert np.all(ratios < 1.0), f"displacements {d}, changes {changes}"
    assert ratios[-1] < 0.75, f"not approaching first order: ratios {ratios}"
    assert changes[-1] < 0.005 * abs(d[-1])
