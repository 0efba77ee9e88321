"""The planner's decision loop on a fake clock: the state-age gate, the three loops, the deadlines."""

import math

import pytest

from frog_planner.core import decision_loop as dl
from frog_planner.core.paths import line_path
from frog_planner.core.planner import Planner
from frog_planner.core.settings import PlannerSettings
from frog_planner.core.transition_model import TransitionModel

PERIOD = 1.5
BOUND = 0.5


class FakeClock:
    def __init__(self, t=100.0):
        self.t = t

    def __call__(self):
        return self.t


@pytest.fixture(scope="module")
def model(synthetic):
    arrays = synthetic.library_arrays(n_states=300, horizon=PERIOD, sample_interval=0.05, seed=0)
    return TransitionModel(arrays["initial_states"], arrays["transitions"][:, :, -1, :].astype(float),
                           list("ABCDEFGHI"), period=PERIOD)


def make_loop(model, clock, paired=False, **settings):
    loop = dl.DecisionLoop(dl.LoopSettings(PERIOD, BOUND, **settings), clock, paired=paired)
    loop.set_planner(Planner(model, line_path(), PlannerSettings(period=PERIOD, depth=1)))
    return loop


POSE, TWIST = (0.0, 0.001, 0.0), (0.02, 0.0, 0.0)


def test_waits_for_a_state_then_decides_on_it_and_carries_its_stamp(model):
    clock = FakeClock()
    loop = make_loop(model, clock)
    out = loop.tick()
    assert out.state == dl.WAITING and "no odometry" in out.message and out.primitive == (8, "I")
    loop.odometry(POSE, TWIST, 99.9)
    out = loop.tick()
    assert out.state == dl.FOLLOWING and out.state_stamp == 99.9 and out.primitive[1] != "I"
    assert loop.state_age() == pytest.approx(0.1) and loop.waited == 1


@pytest.mark.parametrize("age, decides", [(0.0, True), (0.49, True), (0.5, True), (0.51, False), (2.0, False),
                                          (-0.6, False)])
def test_the_state_age_gate_is_exactly_max_state_age_s(model, age, decides):
    clock = FakeClock()
    loop = make_loop(model, clock)
    loop.odometry(POSE, TWIST, clock.t - age)
    out = loop.tick()
    assert (out.state == dl.FOLLOWING) == decides, out.message
    if not decides:
        assert out.state == dl.WAITING and ("old" in out.message or "future" in out.message)
        assert out.primitive == (8, "I") and out.state_stamp is None


def test_a_predicted_pose_rests_on_the_last_frame_the_tag_was_seen_in(model):
    """The tracker coasts: odometry stamped now, but its state is the frame 0.6 s ago."""
    clock = FakeClock()
    loop = make_loop(model, clock, paired=True)
    loop.odometry(POSE, TWIST, clock.t - 0.03)
    assert loop.tick().state == dl.WAITING          # no tracker state for it yet: not usable
    loop.tracker_state(clock.t - 0.03, clock.t - 0.6)
    out = loop.tick()
    assert out.state == dl.WAITING and "0.600 s old" in out.message
    # the tag seen again: the tracker state may come before the odometry
    loop.tracker_state(clock.t - 0.01, clock.t - 0.01)
    loop.odometry(POSE, TWIST, clock.t - 0.01)
    out = loop.tick()
    assert out.state == dl.FOLLOWING and out.state_stamp == pytest.approx(clock.t - 0.01)


def test_a_state_that_ages_past_the_bound_while_deciding_is_refused(model):
    clock = FakeClock()
    loop = make_loop(model, clock)
    loop.odometry(POSE, TWIST, clock.t - 0.45)
    decide = loop.planner.decide

    def slow_decide(*a, **k):               # a loaded machine: the search takes 0.1 s
        clock.t += 0.1
        return decide(*a, **k)
    loop.planner.decide = slow_decide
    out = loop.tick()
    assert out.state == dl.WAITING and "0.550 s old" in out.message


def test_a_stopped_tracker_then_fresh_states_after_it(model):
    """SIGSTOP of the tracker for 5 s: the loop waits from the bound on and follows on the first fresh state."""
    clock = FakeClock()
    loop = make_loop(model, clock)
    states = []
    for k in range(40):                     # 0.1 s steps; poses only until 0.2 s, then from 3.0 s
        t = clock.t
        if k <= 2 or k >= 30:
            loop.odometry(POSE, TWIST, t - 0.03)
        out = loop.tick()
        states.append((round(k * 0.1, 1), out.state))
        clock.t += 0.1
    waiting = [t for t, s in states if s == dl.WAITING]
    # the last pose before the stop was captured at 0.17 s: its state passes the bound at 0.67 s
    assert waiting[0] == pytest.approx(0.7) and waiting[-1] == pytest.approx(2.9)
    assert all(s == dl.FOLLOWING for t, s in states if t < 0.67 or t >= 3.0)


def test_logs_once_per_state_and_reason_not_per_age(model):
    clock = FakeClock()
    loop = make_loop(model, clock)
    loop.odometry(POSE, TWIST, clock.t - 1.0)
    first = loop.tick()
    clock.t += 0.5
    second = loop.tick()
    assert first.logs and first.logs[0][0] == "warn" and "publishing primitive I" in first.logs[0][1]
    assert second.logs == ()
    loop.odometry(POSE, TWIST, clock.t)
    assert loop.tick().logs[0] == ("info", "following the line path")


def test_idle_start_stop_and_no_library(model):
    clock = FakeClock()
    loop = make_loop(model, clock)
    loop.odometry(POSE, TWIST, clock.t)
    loop.stop()
    assert loop.tick().state == dl.IDLE
    assert loop.start() is None and loop.tick().state == dl.FOLLOWING
    loop.set_planner(None, "cannot use library 'x.npz': missing")
    out = loop.tick()
    assert out.state == dl.ERROR and "x.npz" in out.message and loop.start() == out.message


def test_the_authors_loop_executes_each_queued_decision_once_and_not_when_stale(model):
    clock = FakeClock()
    loop = make_loop(model, clock, replan_interval=0.3)
    for k in range(9):                       # 9 states over 0.27 s, then the replan
        loop.odometry((0.0, 0.001 * k, 0.0), TWIST, clock.t)
        clock.t += 0.03
    assert loop.replan() is None and loop.queued[2] == 9
    out = loop.tick()
    assert out.state == dl.FOLLOWING and "mean of 9 states" in out.message
    assert loop.tick().state == dl.WAITING           # none new since: I
    loop.odometry(POSE, TWIST, clock.t)
    loop.replan()
    clock.t += 0.6                                   # the tick comes after the bound; a fresh state has
    loop.odometry(POSE, TWIST, clock.t)              # come since, but the queued decision rests on the old one
    out = loop.tick()
    assert out.state == dl.WAITING and "queued decision" in out.message


def test_simulator_mode_deadline_fallback_and_staleness(model):
    clock = FakeClock()
    loop = make_loop(model, clock, transitions="simulator", decision_deadline=0.2)
    loop.odometry(POSE, TWIST, clock.t - 0.05)
    req = loop.tick()
    assert isinstance(req, dl.RolloutRequest) and req.deadline == pytest.approx(clock.t + 0.3)
    assert req.lead == pytest.approx(0.35)
    clock.t = req.deadline
    loop.odometry(POSE, TWIST, clock.t - 0.03)        # reanchored on the newest state
    out = loop.finish(None, "rollouts missed the deadline")
    assert out.state == dl.FOLLOWING and loop.fallback_decisions == 1 and out.state_stamp == pytest.approx(
        clock.t - 0.03)
    assert any("library decision instead" in text for _, text in out.logs)
    # the state ages past the bound before the deadline (a stopped tracker): refused
    req = loop.tick()
    clock.t = req.deadline + 0.5
    out = loop.finish(None, "rollouts missed the deadline")
    assert out.state == dl.WAITING and loop.fallback_decisions == 1


def test_goal_reached_publishes_no_action(model):
    clock = FakeClock()
    loop = make_loop(model, clock)
    end = loop.planner.path.points[-1]
    loop.planner.reset(0.999)
    loop.odometry((float(end[0]), float(end[1]), 0.0), TWIST, clock.t)
    out = loop.tick()
    assert out.state == dl.GOAL_REACHED and out.primitive == (8, "I")
    assert loop.tick().state == dl.GOAL_REACHED and math.isfinite(loop.state_age())
