"""Hardware transitions: checked on logs the simulator writes itself."""
import numpy as np
import pytest

from frog_sim.core import hardware_runs as hr
from frog_sim.core.simulation import FrogSimulation


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory):
    """A 14-decision log with frame jitter, pose noise, a tag offset and a start-up burst."""
    path = tmp_path_factory.mktemp("hw") / "synthetic_run.csv"
    seq = list("FBCEEBDFFCBHGB")
    return hr.synthesize_log(FrogSimulation(), seq, path, period=1.43, first_decision=1.0, latency=0.1,
                             frame_jitter=0.015, position_noise=0.0008, heading_noise=np.radians(0.5),
                             tag_offset=np.radians(-6.0), burst_rows=50, seed=3)


def test_burst_is_dropped_and_decision_times_recovered(synthetic):
    log = hr.read_hardware_log(synthetic.path)
    assert log.dropped_rows == synthetic.burst_rows
    assert np.all(np.diff(log.time) > 0.04)                   # only real frames remain
    fit = hr.fit_decision_times(log)
    assert fit.period == pytest.approx(synthetic.period, abs=0.003)
    assert fit.t0 == pytest.approx(synthetic.decision_times[0], abs=0.025)
    assert fit.residual_rms < fit.frame_interval               # "residuals about one frame"
    est = fit.decision_times(t_end=synthetic.decision_times[-1] + 0.05)
    assert len(est) == len(synthetic.decision_times)
    assert np.abs(est - synthetic.decision_times).max() < 0.04


def test_transitions_match_the_simulated_truth(synthetic):
    log = hr.read_hardware_log(synthetic.path)
    measured = hr.measure_transitions(log, tag_offset=synthetic.tag_offset)
    truth = {t.index: t for t in synthetic.truth}
    assert len(measured) >= len(truth) - 1                     # the last may run past the log's end
    turned = 0.0
    for m in measured:
        t = truth[m.index]
        assert m.primitive == t.primitive and m.previous == t.previous
        assert abs(m.dx - t.dx) < 0.0025 and abs(m.dy - t.dy) < 0.0025, (m, t)
        assert abs(m.dheading - t.dheading) < np.radians(1.0), (m, t)
        assert abs(m.forward - t.forward) < 0.006 and abs(m.lateral - t.lateral) < 0.006, (m, t)
        assert abs(m.yaw_rate - t.yaw_rate) < np.radians(4.0), (m, t)
        turned += abs(t.dheading)
    assert turned > np.radians(20)                              # the sequence does turn


def test_a_wrong_tag_offset_shows_as_side_slip(synthetic):
    """Same log read with the offset ignored: every period then slips sideways by -dx sin(6 deg)."""
    log = hr.read_hardware_log(synthetic.path)
    right = {m.index: m for m in hr.measure_transitions(log, tag_offset=synthetic.tag_offset)}
    wrong = {m.index: m for m in hr.measure_transitions(log, tag_offset=0.0)}
    for k, m in right.items():
        rotated = -m.dx * np.sin(np.radians(6.0)) + m.dy * np.cos(np.radians(6.0))   # frame turned +6 deg
        assert wrong[k].dy == pytest.approx(rotated, abs=1e-6)
        assert wrong[k].dheading == pytest.approx(m.dheading, abs=1e-9)


def test_period_fit_from_sparse_changes_by_hand():
    """Changes at k = 0, 3, 4, 9, 11 of T0 = 2.0 s, P = 1.125 s, seen at the next 70 ms frame."""
    frames = np.arange(0.0, 16.0, 0.07)
    act = np.array(["I"] * len(frames))
    letters = {0: "F", 3: "B", 4: "C", 9: "E", 11: "D"}
    cur = "I"
    for k in range(13):
        cur = letters.get(k, cur)
        act[frames >= 2.0 + 1.125 * k] = cur
    log = hr.HardwareLog("hand", frames, frames * 0, frames * 0, frames * 0, act)
    fit = hr.fit_decision_times(log)
    assert fit.period == pytest.approx(1.125, abs=0.004)
    assert fit.t0 == pytest.approx(2.0, abs=0.036)
    assert list(fit.change_index) == [0, 3, 4, 9, 11]


def test_burst_end_by_hand():
    stamps = np.concatenate([np.arange(10) * 0.001, 0.08 + np.arange(10) * 0.07])
    assert hr.burst_end(stamps) == 10
    stamps = np.arange(20) * 0.07
    assert hr.burst_end(stamps) == 0
    with pytest.raises(ValueError, match="never settles"):
        hr.burst_end(np.arange(20) * 0.001)


def test_bad_rows_are_named(tmp_path):
    p = tmp_path / "bad.csv"
    p.write_text("logger\nheader\n1,0.1,0.2,0.3,0,0,0,0,B\n2,x,0.2,0.3,0,0,0,0,B\n")
    with pytest.raises(ValueError, match=r"bad.csv:4: expected"):
        hr.read_hardware_log(p)
    p.write_text("logger\nheader\n" + "".join(f"{70 * i},0.1,0.2,0.3,0,0,0,0,Z\n" for i in range(12)))
    with pytest.raises(ValueError, match=r"bad.csv:3: last column 'Z'"):
        hr.read_hardware_log(p)


def test_real_logs_match_the_readme_facts(measured_file):
    """README: periods 1.42-1.44 s (sin4: 1.125 s), residuals about a frame, tag about -6 deg."""
    folder = measured_file("hardware_runs/line1.csv").parent
    logs = hr.read_hardware_runs(folder)
    for name, log in logs.items():
        assert 30 < log.dropped_rows < 70, name                    # "a burst of about 50 rows"
        fit = hr.fit_decision_times(log)
        expected = (1.12, 1.13) if name == "sin4" else (1.42, 1.44)
        assert expected[0] <= fit.period <= expected[1], (name, fit.period)
        assert fit.residual_rms < fit.frame_interval, name
    mean, sd, n = hr.estimate_tag_offset([logs["line1"], logs["line2"]])
    assert n >= 10 and np.degrees(mean) == pytest.approx(-6.0, abs=3.0) and np.degrees(sd) < 8
