"""N-period replays against the hardware logs, scored on runs the calibration did not see.

``frog_sim/data/replay_calibration.json`` is the record of ``frog-sweep calibrate-replays``:
the calibrated values (today's defaults) and, for each fold of the leave-one-run-out
cross-validation, the parameters chosen without that run. Here every run is replayed again
with its fold's parameters (independent truth: the robot's logged poses) and the held-out
replays, pooled, are scored at the targets: the heading ratio sim/real within 0.85-1.15 for
N = 1..4 periods on the ellipses and on the lines and sines separately, the RMS heading error
after 3 periods at most 8 deg.
"""
import json
from importlib.resources import files

import numpy as np
import pytest

from frog_sim import multi_period as mp
from frog_sim import replay_calibration as rc
from frog_sim.core import hardware_runs as hr
from frog_sim.core.model_parameters import FrogParameters
from frog_sim.core.simulation import FrogSimulation


def _record():
    return json.loads(files("frog_sim").joinpath("data", "replay_calibration.json").read_text())


def test_defaults_are_the_shipped_calibration():
    rec = _record()
    for name, value in rec["calibrated"].items():
        assert getattr(FrogParameters(), name) == pytest.approx(value, rel=1e-6), name


def test_every_run_is_held_out_once():
    folds = _record()["cross_validation"]
    held = [r for f in folds for r in f["held_out"]]
    assert sorted(held) == sorted(hr.HARDWARE_RUNS)
    assert all(not set(f["held_out"]) & set(f["train"]) for f in folds)


@pytest.fixture(scope="module")
def windows(measured_file):
    folder = measured_file("hardware_runs/line1.csv").parent
    logs = hr.read_hardware_runs(folder)
    offset, _, _ = hr.estimate_tag_offset([logs["line1"], logs["line2"]])
    return mp.real_windows(logs, offset, max(rc.N_RATIO))


def _replayed(params, wins):
    sim = FrogSimulation(params)
    out = [mp.ReplayWindow(**{**w.__dict__, "sim": [], "curve": {}}) for w in wins]
    for w in out:
        mp.simulate_window(sim, w, hr.DECISION_TO_FIRING_S)
    return out


@pytest.fixture(scope="module")
def held_out(windows):
    """Every run's windows replayed with the parameters chosen without it."""
    out = []
    for fold in _record()["cross_validation"]:
        params = FrogParameters().replace(**fold["chosen"])
        out += _replayed(params, [w for w in windows if w.run in fold["held_out"]])
    return out


def _group(wins, group):
    return mp.window_metrics([w for w in wins if rc.run_group(w.run) == group], max(rc.N_RATIO))


@pytest.mark.slow
@pytest.mark.parametrize("group", ["ellipse", "line/sine"])
def test_held_out_runs_turn_as_the_robot_over_one_to_four_periods(held_out, group):
    m = _group(held_out, group)
    ratios = [m[n]["heading_ratio"] for n in rc.N_RATIO]
    assert all(1 - rc.RATIO_TOLERANCE <= r <= 1 + rc.RATIO_TOLERANCE for r in ratios), ratios


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="not met: held out, the RMS heading error after 3 periods is 10.9 deg "
                   "(ellipses 8.9, lines and sines 12.7; the model before 11.2 on all runs) against the 8 deg target; "
                   "the robot's residual per period alone, with its autocovariance, gives about 10 deg "
                   "(frog-sim disturbance)")
def test_held_out_rms_heading_error_after_three_periods(held_out):
    m = mp.window_metrics(held_out, 3)
    assert np.degrees(m[3]["rms_heading_error"]) <= np.degrees(rc.RMS_HEADING_3_TARGET)


@pytest.mark.slow
def test_held_out_ellipses_turn_closer_to_the_robot_than_the_model_before(windows, held_out):
    """Sustained turns: the model without the waterline friction turns the ellipses 18 % too much after
    4 periods (its turn carries into the next periods); held out, the calibrated model is closer at every
    N = 2..4."""
    before = _group(_replayed(FrogParameters().replace(**rc.PREVIOUS_MODEL),
                              [w for w in windows if rc.run_group(w.run) == "ellipse"]), "ellipse")
    after = _group(held_out, "ellipse")
    assert before[4]["heading_ratio"] > 1.15, before[4]
    for n in (2, 3, 4):
        assert abs(after[n]["heading_ratio"] - 1) < abs(before[n]["heading_ratio"] - 1), (n, after[n], before[n])
