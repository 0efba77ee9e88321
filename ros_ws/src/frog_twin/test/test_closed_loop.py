"""Closed loop on the real DER simulator with a small real library (frog_sim generates it).

Distances are checked against geometry computed here (the analytic line and circle), not
against the evaluator's own distance column.
"""

import math

import numpy as np
import pytest

from frog_planner.core.paths import line_path, parametric_path
from frog_planner.core.transition_model import TransitionModel
from frog_planner.core.settings import PlannerSettings
from frog_twin.core.evaluation import run_closed_loop

PERIOD = 1.5


@pytest.fixture(scope="module")
def library(tmp_path_factory):
    gen = pytest.importorskip("frog_sim.core.motion_library")
    path = tmp_path_factory.mktemp("lib") / "small.npz"
    spec = gen.LibrarySpec(n_states=150, horizon=PERIOD, seed=11)
    return gen.generate_library(spec, path, workers=2, chunk_size=10, progress=False)


def _distance_to_x_axis(pose):
    """The line y = 0 (x >= 0) of line_path(): distance is |y| while x lies along it."""
    return np.abs(pose[:, 1])


def test_closed_loop_reduces_a_5cm_lateral_offset(library):
    """The simulated frog turns slowly (a one-sided kick turns it a few degrees), so the loop
    needs a few periods; over the last quarter of the run the offset must have shrunk.
    With the paper's cost (heading error against the tangent at the closest point) turning
    towards the path costs heading and progress at once and depth 1 never turns back; the
    heading look-ahead makes the heading term point back to the path. With the paper's
    w_b = 50 the progress term still wins on a 60 cm line (B gains ~2 cm per period, a turn
    only a few degrees), so this run weighs heading three times more (w_b = 150)."""
    model = TransitionModel.load(library, period=PERIOD, gradient_correction=True)
    path = line_path(length=0.6)
    res = run_closed_loop(path, model, PlannerSettings(period=PERIOD, w_heading=150.0),
                          start_offset=(0.0, 0.05, 0.0), max_time=60.0)
    inside = (res.pose[:, 0] >= -0.01) & (res.pose[:, 0] <= path.length)   # beside the line, not past it
    d = _distance_to_x_axis(res.pose)
    assert d[0] == pytest.approx(0.05, abs=1e-3)
    late = d[(res.time >= 0.75 * res.time[-1]) & inside]
    assert late.mean() < 0.7 * 0.05, f"still {late.mean() * 100:.1f} cm from the path at the end"
    # the planner's own bookkeeping agrees with the independent distance
    assert res.decisions[0]["distance_to_path"] == pytest.approx(0.05, abs=2e-3)
    assert res.metrics["final_progress"] > 0.5


def test_straight_start_stays_on_the_line(library):
    model = TransitionModel.load(library, period=PERIOD, gradient_correction=True)
    path = line_path(length=0.30)
    res = run_closed_loop(path, model, PlannerSettings(period=PERIOD), max_time=40.0)
    assert res.metrics["goal_reached"]
    d = _distance_to_x_axis(res.pose)
    assert d.mean() < 0.01 and d.max() < 0.03
    end = res.pose[-1, :2]
    assert math.hypot(*(end - path.points[-1])) < 0.05      # finished at the end, not beside it
    assert np.all(np.diff([x["progress"] for x in res.decisions]) >= 0)


RADIUS = 0.30          # m: a right-hand arc (the frog turns right with E, 0110)
ARC_ANGLE = 1.0        # rad: 30 cm of path; the chord misses the arc's end by 13.8 cm


def test_follows_a_right_hand_arc(library):
    """A right-hand arc of radius 30 cm, 30 cm long (about three times the frog's tightest
    steady turn). Tolerance: mean distance to the circle <= 3.5 cm, max <= 9 cm, and the robot
    gets past 90 % of the arc (the goal radius; measured with the issue-11 library: 2.6 cm mean, 7.5 cm max).
    Heading weighs w_b = 150 here: with the default w_b = 50 the progress term keeps the
    frog too straight on curves (5.5 cm mean, 16 cm max on this arc), while w_b >= 100 stalls
    depth 1 at the steep start of the paper's sinusoid, so the default stays at 50."""
    def arc(s):
        a = ARC_ANGLE * s
        return np.column_stack([RADIUS * np.sin(a), -RADIUS * (1.0 - np.cos(a))])

    path = parametric_path(arc, name="arc")
    model = TransitionModel.load(library, period=PERIOD, gradient_correction=True)
    res = run_closed_loop(path, model, PlannerSettings(period=PERIOD, w_heading=150.0), max_time=45.0)
    centre = np.array([0.0, -RADIUS])
    rel = res.pose[:, :2] - centre
    d = np.abs(np.hypot(rel[:, 0], rel[:, 1]) - RADIUS)          # distance to the circle
    swept = np.arctan2(rel[:, 0], rel[:, 1])                      # 0 at the start, clockwise > 0
    # the run ends at the planner's goal radius: 93 % of the arc with the issue-18 frog, which
    # turns less per kick and reaches the radius from the inside (95 % with the issue-11 one)
    assert swept.max() >= 0.90 * ARC_ANGLE, f"got only {swept.max() / ARC_ANGLE:.0%} along the arc"
    assert d.mean() <= 0.035 and d.max() <= 0.09, (d.mean(), d.max())
    used = res.metrics["primitives_used"]
    right, left = sum(used.get(p, 0) for p in "CEG"), sum(used.get(p, 0) for p in "DFH")
    assert right > left, used       # right-turning primitives (C, E, G) carry a right-hand arc


def test_simulator_transitions_from_the_full_state_predict_the_next_pose_exactly(library):
    """Rollouts from the simulator's full state with its own steps and tolerance (uniform 2 ms,
    1e-6 N) are the trajectory ``FrogSimulation.step`` computes, so the pose the search predicts
    for the chosen primitive is the pose the robot then reaches, to the Newton tolerance
    (the world is the nominal robot: no limb spread, no disturbance)."""
    from frog_sim.core.rollouts import Rollouts
    from frog_twin.core.evaluation import SimulatorTransitions
    model = TransitionModel.load(library, period=PERIOD, gradient_correction=True)
    path = line_path(length=0.30)
    with Rollouts(coast_time_step=0.002, force_tolerance=1e-6, threads=1) as ro:
        res = run_closed_loop(path, model, PlannerSettings(period=PERIOD), max_time=4.0, transitions="simulator",
                              simulator=SimulatorTransitions(ro, start="exact"), start_offset=(0.0, 0.02, 0.0),
                              sample_interval=PERIOD)
    assert len(res.decisions) >= 3
    assert res.metrics["transitions"] == "simulator" and res.metrics["metric"] == "simulator-exact"
    for k, dec in enumerate(res.decisions[:-1]):
        reached = res.pose[k + 1]
        assert np.abs(np.asarray(dec["predicted_pose"]) - reached).max() < 1e-7, (k, dec["predicted_pose"], reached)
    with pytest.raises(ValueError, match="depth 1-2"):
        run_closed_loop(path, model, PlannerSettings(depth=3, period=PERIOD), max_time=2.0,
                        transitions="simulator")


def test_simulator_transitions_from_the_estimate_and_a_lead(library):
    """From what a robot knows (pose, twist, firing times), with the decision executed 1 s after
    its observation (planner_node's deadline): each decision's predicted pose, one period after
    the execution, is where the nominal robot then is, within what the estimate leaves out (the
    limbs' own motion relative to the body: bench/planner_rollouts.py, up to 1.5 mm and 1.2 deg
    one period on when estimated mid-stroke, as 1 s before a firing is), and the run executes at
    the observation + lead (the decision times are the period's multiples)."""
    from frog_sim.core.rollouts import Rollouts
    from frog_twin.core.evaluation import SimulatorTransitions
    model = TransitionModel.load(library, period=PERIOD, gradient_correction=True)
    path = line_path(length=0.30)
    with Rollouts(threads=1) as ro:
        res = run_closed_loop(path, model, PlannerSettings(period=PERIOD), max_time=6.5, transitions="simulator",
                              simulator=SimulatorTransitions(ro, lead=1.0), start_offset=(0.0, 0.02, 0.0),
                              sample_interval=0.5)
    assert res.metrics["lead_s"] == 1.0 and res.metrics["metric"] == "simulator-estimated"
    times = [d["time"] for d in res.decisions]
    assert times == pytest.approx([k * PERIOD for k in range(len(times))])
    for dec in res.decisions[:-1]:
        at = dec["time"] + 1.0 + PERIOD                       # executed after the lead, one period on
        k = int(np.argmin(np.abs(res.time - at)))
        assert res.time[k] == pytest.approx(at, abs=1e-6)
        err = np.asarray(dec["predicted_pose"]) - res.pose[k]
        assert np.hypot(*err[:2]) < 2e-3 and abs(err[2]) < math.radians(2.0), (dec["time"], err)
    with pytest.raises(ValueError, match="shorter than the period"):
        run_closed_loop(path, model, PlannerSettings(period=PERIOD), max_time=2.0, transitions="simulator",
                        simulator=SimulatorTransitions(ro, lead=PERIOD))


def test_turning_response_mirrors_and_matches_its_own_track():
    """Mirrored primitives (E right, F left) settle into mirrored circles; the fitted steady
    radius agrees with speed / yaw rate of a steady circle; the yaw rate builds up within a
    few periods. Path radii are checked against their closed forms."""
    from frog_planner.core.paths import ellipse_path, sinusoid_path
    from frog_twin.core.evaluation import path_min_radius, turning_response

    e = turning_response("E", period=PERIOD)
    f = turning_response("F", period=PERIOD)
    assert e.steady_radius == pytest.approx(f.steady_radius, rel=1e-4)
    assert e.steady_yaw_rate == pytest.approx(-f.steady_yaw_rate, rel=1e-4) and e.steady_yaw_rate < 0
    assert e.steady_radius == pytest.approx(e.steady_speed / abs(e.steady_yaw_rate), rel=0.15)
    # the real robot reaches 63 % of its steady E/F yaw rate within ~2.3 s; the
    # earlier simulator took ~12 s (several periods), today's within the first periods
    assert 0 < e.rise_time < 3 * PERIOD
    assert path_min_radius(line_path()) == math.inf
    # circle of radius l/2 (A = 1); sinusoid y = (l/A) sin(f x / l): min radius l A / f^2 at the
    # peaks, which the 100-point resampling (paper) rounds off by a few per cent
    assert path_min_radius(ellipse_path(length=0.3, A=1.0)) == pytest.approx(0.15, rel=1e-3)
    assert path_min_radius(sinusoid_path(length=0.357, A=8.5, f=10.0)) == pytest.approx(0.357 * 8.5 / 100, rel=0.05)
