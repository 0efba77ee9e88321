"""Leave-one-run-out cross-validation of the replay calibration (frog_sim.replay_calibration) on
synthetic windows whose answers are known by construction: a candidate that turns each run by a
known factor of the robot's turn, so the fold's choice and the held-out ratios follow by hand."""
import numpy as np
import pytest

from frog_sim import multi_period as mp
from frog_sim import replay_calibration as rc


def _windows():
    """Two windows per run, 2 periods, turns of 10 and -20 deg per period, 30 mm forward, 5 mm aside."""
    out = []
    for run in ("line1", "sin1", "ellipse1"):
        for k, turn in enumerate((10.0, -20.0)):
            h = np.radians(turn)
            out.append(mp.ReplayWindow(run=run, index=k, time=1.0 + k, period=1.43, primitives=["E", "E"],
                                       forward=0.02, lateral=0.0, yaw_rate=0.0,
                                       real=[[0.03, 0.005, h], [0.06, 0.01, 2 * h]]))
    return out


def _evaluation(windows, factors, values):
    """The robot's ends with each run's heading scaled by ``factors[run]`` (distances unchanged)."""
    ends = [[[x, y, factors[w.run] * h] for x, y, h in w.real] for w in windows]
    return rc.ReplayEvaluation(values=values, windows=ends, kick_ratio=0.1,
                               repeated_yaw_rate=rc.REPEATED_TARGET, speeds={})


def test_each_run_is_scored_with_the_point_chosen_without_it():
    wins = _windows()
    obj = rc.ReplayObjective(wins, [], [])
    # a: right on line1 and sin1, turns ellipse1 twice as much; b: 1.3 everywhere; c: 0.95 on the
    # lines and sines, 1.0 on the ellipse
    a = _evaluation(wins, {"line1": 1.0, "sin1": 1.0, "ellipse1": 2.0}, {"waterline_friction": 0.001})
    b = _evaluation(wins, {"line1": 1.3, "sin1": 1.3, "ellipse1": 1.3}, {"waterline_friction": 0.002})
    c = _evaluation(wins, {"line1": 0.95, "sin1": 0.95, "ellipse1": 1.0}, {"waterline_friction": 0.003})
    assert obj.metrics(b)["groups"]["ellipse"][2]["heading_ratio"] == pytest.approx(1.3)
    assert obj.metrics(b)["distance"][2] == pytest.approx(1.0)
    cv = rc.cross_validate(obj, [a, b, c])
    assert [f["held_out"] for f in cv] == [["ellipse1"], ["line1"], ["sin1"]]
    # without ellipse1, a is exact (cost of the ratios 0) and c is 0.95: a is chosen, and on
    # ellipse1 it turns twice as much
    assert cv[0]["chosen"] == a.values
    assert cv[0]["held_out_metrics"]["replays"]["1"]["heading_ratio"] == pytest.approx(2.0)
    # without line1: a pays ellipse1's 2.0 ((1 / 0.15)^2 per N), c only sin1's 0.95: c is chosen
    assert cv[1]["chosen"] == c.values and cv[2]["chosen"] == c.values
    held = rc.held_out_summary(rc.held_out_windows(obj, [a, b, c], cv))
    # pooled held out: line1 and sin1 at 0.95, ellipse1 at 2.0 (least-squares slope over all windows)
    assert held["groups"]["line/sine"][1]["heading_ratio"] == pytest.approx(0.95)
    assert held["groups"]["ellipse"][2]["heading_ratio"] == pytest.approx(2.0)
    assert held["per_run"]["sin1"][2]["heading_ratio"] == pytest.approx(0.95)
    assert held["pooled"][1]["heading_ratio"] == pytest.approx((2 * 0.95 + 2.0) / 3)
    assert set(held["per_run"]) == {"line1", "sin1", "ellipse1"}


def test_the_ratio_terms_are_per_group_at_the_targets_tolerance():
    wins = _windows()
    obj = rc.ReplayObjective(wins, [], [])
    ev = _evaluation(wins, {"line1": 1.15, "sin1": 1.15, "ellipse1": 0.85}, {"waterline_friction": 0.0})
    t = obj.terms(ev)
    for n in (1, 2):      # at the edges of 0.85-1.15: each term 1
        assert t[f"ratio_line/sine_{n}"] == pytest.approx(1.0)
        assert t[f"ratio_ellipse_{n}"] == pytest.approx(1.0)
    assert t["distance_2"] == pytest.approx(0.0) if "distance_2" in t else True
    assert "ratio_ellipse_3" not in t            # two-period windows: no N = 3


def test_the_choice_keeps_the_targets_before_the_cost():
    """a turns the lines and sines 16 % too much (two ratios just outside 0.85-1.15) and is cheaper
    than b, which turns them 10 % and the ellipse 14 % too much, inside every target: b is chosen."""
    wins = _windows()
    obj = rc.ReplayObjective(wins, [], [])
    a = _evaluation(wins, {"line1": 1.16, "sin1": 1.16, "ellipse1": 1.0}, {"waterline_friction": 0.001})
    b = _evaluation(wins, {"line1": 1.10, "sin1": 1.10, "ellipse1": 1.14}, {"waterline_friction": 0.002})
    assert obj.cost(a) < obj.cost(b)
    assert not obj.targets(a)["ratio_line/sine_1"] and all(obj.targets(b).values())
    assert min([a, b], key=obj.rank_key) is b
