"""The robot's own loop for --paper-cost replays: which node parameters, and --node-param wins."""
import argparse

from frog_common.state_age import MAX_STATE_AGE_S
from frog_sim.core.hardware_runs import DECISION_TO_FIRING_S
from frog_twin.replay_cli import PAPER_REPLAN_INTERVAL_S, _merged, direct_loop_params, paper_loop_params


def _args(**kw):
    base = {"paper_cost": True, "ideal_loop": False, "no_vision": False, "direct": False}
    base.update(kw)
    return argparse.Namespace(**base)


def test_paper_cost_runs_the_robots_loop_unless_ideal():
    # their loop fires on states up to one replan interval older: the bound grows by it, in both hops
    bound = PAPER_REPLAN_INTERVAL_S + MAX_STATE_AGE_S
    planner = {"replan_interval": PAPER_REPLAN_INTERVAL_S, "lookup": "authors_code", "max_state_age_s": bound}
    assert paper_loop_params(_args()) == {"planner_node": planner, "tracker_node": {"estimator": "frame_difference"},
                                          "bridge_node": {"max_state_age_s": bound}}
    # without vision there is no tracker, without the link no bridge: the planner's loop alone
    assert paper_loop_params(_args(no_vision=True, direct=True)) == {"planner_node": planner}
    assert paper_loop_params(_args(ideal_loop=True)) == {}
    assert paper_loop_params(_args(paper_cost=False)) == {}
    # 9 polled states at the ~14 fps each consumer of the authors' tracker got (hardware_runs README)
    assert 9 * 0.068 < PAPER_REPLAN_INTERVAL_S < 9 * 0.072


def test_user_node_params_override_the_loop_and_inputs_stay_unchanged():
    loop = paper_loop_params(_args())
    user = {"planner_node": {"replan_interval": 0.0, "depth": 2}, "camera_sim": {"fps": 14.0}}
    out = _merged(loop, user)
    assert out["planner_node"] == {"replan_interval": 0.0, "depth": 2, "lookup": "authors_code",
                                   "max_state_age_s": PAPER_REPLAN_INTERVAL_S + MAX_STATE_AGE_S}
    assert out["tracker_node"] == {"estimator": "frame_difference"} and out["camera_sim"] == {"fps": 14.0}
    assert loop["planner_node"]["replan_interval"] == PAPER_REPLAN_INTERVAL_S      # not mutated


def test_direct_replay_fires_at_the_robots_delay_beside_the_paper_loop():
    # without the serial link sim_node stands for relay, BLE and firmware: the delay in simulated time
    assert direct_loop_params(_args(direct=True)) == {"sim_node": {"command_delay_s": DECISION_TO_FIRING_S}}
    assert direct_loop_params(_args(direct=False)) == {}
    both = _merged(paper_loop_params(_args(no_vision=True, direct=True)), direct_loop_params(_args(direct=True)))
    assert both["sim_node"] == {"command_delay_s": DECISION_TO_FIRING_S}
    assert both["planner_node"]["max_state_age_s"] == PAPER_REPLAN_INTERVAL_S + MAX_STATE_AGE_S
    assert "bridge_node" not in both
