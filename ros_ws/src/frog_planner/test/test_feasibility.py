"""Feasibility: steady turning circles from a model, tight stretches of a path, the turning-limited floor.

Truth comes from outside the code under test: the synthetic library's kinematics settle to a
constant twist (u, w), whose circle has radius u / w exactly; paths built from hand-placed
arcs have known curvature where they were put; the straight cut of a circular arc has a mean
distance to the arc of R - mean |p - c| over the chord, integrated here by quadrature.
"""

import math

import numpy as np
import pytest

from frog_planner.core.feasibility import (SteadyTurn, TurningLimits, radius_ahead, steady_turns, tight_stretches,
                                           turning_limited_floor, turning_limits)
from frog_planner.core.paths import Path, sinusoid_path
from frog_planner.core.transition_model import TransitionModel

PERIOD = 1.5


@pytest.fixture(scope="module")
def model(synthetic):
    lib = synthetic.library_arrays(n_states=300, horizon=2.0, seed=3)
    ti = int(np.argmin(np.abs(lib["times"] - PERIOD)))
    return TransitionModel(lib["initial_states"], lib["transitions"][:, :, ti, :], list(lib["primitive_names"]),
                           list(lib["primitive_bits"]), period=PERIOD, gradient_correction=True)


def arc_path(radius, angle, lead=0.0, tail=0.0, n=400, goal_tolerance=0.005):
    """Straight ``lead`` m, a left arc of ``radius`` through ``angle`` rad, straight ``tail`` m."""
    pts = [np.array([0.0, 0.0])]
    if lead:
        pts.append(np.array([lead, 0.0]))
    phi = np.linspace(0.0, angle, 4000)
    arc = np.column_stack([lead + radius * np.sin(phi), radius * (1 - np.cos(phi))])
    pts.extend(arc[1:])
    if tail:
        end, h = arc[-1], angle
        pts.append(end + tail * np.array([math.cos(h), math.sin(h)]))
    return Path(np.array(pts), n_points=n, goal_tolerance=goal_tolerance)


def test_steady_circles_are_the_twist_ratio_of_the_kinematics(model, synthetic):
    turns = {t.primitive: t for t in steady_turns(model, PERIOD)}
    for name, (u, _, w) in zip("ABCDEFGHI", synthetic.TARGETS):
        t = turns[name]
        if abs(w) > 0:
            assert t.radius_m == pytest.approx(u / abs(w), rel=0.03), name
            assert t.side == np.sign(w)
            assert t.yaw_per_period_rad == pytest.approx(w * PERIOD, rel=0.03)
            assert t.speed_m_per_s == pytest.approx(u, rel=0.03)   # along the circle, chords of 1.5 s
        elif u > 0:
            assert t.radius_m == math.inf and t.side == 0, name
    lim = turning_limits(tuple(turns.values()))
    # G and H (u 5 mm/s, w 0.5 rad/s) are the tightest: 1 cm; I does not move and does not count
    assert lim.left_m == pytest.approx(0.005 / 0.5, rel=0.03)
    assert lim.right_m == pytest.approx(0.005 / 0.5, rel=0.03)
    assert "left 1.0 cm (G)" in lim.describe()
    slow = turning_limits(tuple(turns.values()), min_speed=0.01)   # G, H (5 mm/s) too slow: C, D
    assert slow.left_m == pytest.approx(0.015 / 0.35, rel=0.03)


def test_no_action_is_no_turn_however_it_drifts():
    """'No action' coasting on a drifting library state (default library: 3 mm/s on a 5 cm circle)
    is not a turn the frog can hold; a limb-firing primitive as slow and as tight is."""
    g = SteadyTurn("G", 0.065, 0.38, 0.017)
    drift = SteadyTurn("I", 0.052, -0.079, 0.0029, acts=False)
    tight = SteadyTurn("X", 0.052, -0.079, 0.0029)
    assert turning_limits((g, drift)).right_m == math.inf
    assert turning_limits((g, drift, tight)).right_m == pytest.approx(0.052)
    assert turning_limits((g, drift)).left_m == pytest.approx(0.065)


def test_steady_turns_mark_the_primitives_that_fire_no_limb(model):
    turns = {t.primitive: t for t in steady_turns(model, PERIOD)}
    bits = dict(zip(model.primitive_names, model.primitive_bits))
    assert bits["I"] == "0000" and not turns["I"].acts
    assert all(t.acts for name, t in turns.items() if name != "I")


def test_tight_stretches_are_where_the_arc_was_placed():
    path = arc_path(0.05, math.pi / 2, lead=0.2, tail=0.2)
    arc_start, arc_end = 0.2, 0.2 + 0.05 * math.pi / 2
    (s,) = tight_stretches(path, TurningLimits(0.073, 0.073, ()))
    assert s["side"] == 1
    assert s["min_radius_m"] == pytest.approx(0.05, rel=0.02)
    # the curvature is a finite difference: it spreads over a sample or two at each end
    assert s["start_m"] == pytest.approx(arc_start, abs=0.003)
    assert s["end_m"] == pytest.approx(arc_end, abs=0.003)
    assert s["start"] == pytest.approx(arc_start / path.length, abs=0.01)
    assert tight_stretches(path, TurningLimits(0.04, 0.04, ())) == []
    # turning right only is limited: a left arc is fine
    assert tight_stretches(path, TurningLimits(0.04, 0.5, ())) == []
    r, side = radius_ahead(path, 0.0, 0.1)
    assert r == math.inf and side == 0
    r, side = radius_ahead(path, arc_start / path.length, 0.05)
    assert r == pytest.approx(0.05, rel=0.02) and side == 1


@pytest.mark.slow
def test_floor_of_a_feasible_arc_is_zero_and_the_straight_cut_matches_quadrature():
    R, phi = 0.2, math.pi / 2
    path = arc_path(R, phi)
    floor = turning_limited_floor(path, TurningLimits(0.07, 0.07, ()))
    assert floor.mean_distance_m < 1e-3
    assert np.linalg.norm(floor.points[-1] - path.points[-1]) < 0.006
    # no turning at all, and the end exactly at the goal: the straight cut, R - |p - c| over the chord
    rigid = turning_limited_floor(arc_path(R, phi, goal_tolerance=1e-5), TurningLimits(math.inf, math.inf, ()))
    c = np.array([0.0, R])
    chord = np.linspace(0.0, 1.0, 20001)[:, None] * path.points[-1]
    expected = float(np.mean(R - np.linalg.norm(chord - c, axis=1)))
    assert rigid.straight_cut_m == pytest.approx(expected, rel=0.01)
    assert rigid.mean_distance_m == pytest.approx(expected, rel=0.01)


@pytest.mark.slow
def test_floor_of_the_paper_sine_grows_with_the_turning_circle_up_to_the_straight_cut():
    path = sinusoid_path()
    floors = [turning_limited_floor(path, TurningLimits(r, r, ())) for r in (0.01, 0.073, 0.2, math.inf)]
    means = [f.mean_distance_m for f in floors]
    assert means[0] < 0.002                       # tighter than the sine: it can follow it
    assert all(a <= b + 5e-4 for a, b in zip(means, means[1:])), means
    assert 0.003 < means[1] < floors[1].straight_cut_m
    # no turning: a straight line, which may end anywhere within the goal tolerance (3 cm), so
    # at most the straight cut to the exact end
    assert means[-1] <= floors[-1].straight_cut_m + 1e-9
    d = np.diff(floors[-1].points, axis=0)
    assert np.ptp(np.arctan2(d[:, 1], d[:, 0])) < 1e-9
    # the curve never bends tighter than allowed
    p = floors[1].points
    d = np.diff(p, axis=0)
    heading = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
    ds = np.linalg.norm(d, axis=1)
    assert np.max(np.abs(np.diff(heading) / ds[1:])) <= 1 / 0.073 * 1.02


def test_bad_arguments_are_named(model):
    with pytest.raises(ValueError, match="period"):
        steady_turns(model, float("nan"))
    with pytest.raises(ValueError, match="settle"):
        steady_turns(model, PERIOD, periods=10, settle=9)


def test_the_curve_gradient_matches_finite_differences():
    from frog_planner.core.feasibility import _curve_gradient, _curve_parts
    rng = np.random.default_rng(1)
    n, per, start = 7, 3, np.array([0.1, -0.2])
    z = np.r_[0.3, 0.4, rng.normal(0.0, 5.0, n)]
    w = rng.normal(size=(n * per + 1, 2))

    def f(z):
        return float(np.sum(w * _curve_parts(start, z[0], z[2:], z[1], per)[0]))
    dh, dl, dk = _curve_gradient(_curve_parts(start, z[0], z[2:], z[1], per), w, per)
    fd = np.array([(f(z + e) - f(z - e)) / 2e-6 for e in np.eye(len(z)) * 1e-6])
    np.testing.assert_allclose(np.r_[dh, dl, dk], fd, atol=1e-7)
