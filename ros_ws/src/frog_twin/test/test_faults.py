"""The fault spec, the campaign plan and the run metrics of frog_twin.core.faults (no ROS)."""

import math

import pytest

from frog_twin.core.faults import (
    CAMPAIGN_FAULTS, FAULT_CLASSES, Fault, FaultSpecError, Observed, Resubscription, campaign_plan, check_against_graph,
    fault_end, fault_report, outcome, parse_faults, recorder_losses, recovery_time, restart_windows)
from frog_twin.core.state_audit import PulseAges


def test_spec_round_trips_through_labels_and_sorts_by_time():
    faults = parse_faults("kill:planner_node@12,restart=no; camera_freeze@4+5 ;frame_drop@1+2,rate=0.3")
    assert [f.kind for f in faults] == ["frame_drop", "camera_freeze", "kill"]
    assert faults[0].rate == 0.3 and faults[1].duration == 5 and not faults[2].restart
    again = parse_faults(";".join(f.label() for f in faults))
    assert again == faults
    assert parse_faults("ble_loss@2+3")[0].rate == 0.8      # the default rate
    # every shipped campaign and class spec parses
    for spec in (*CAMPAIGN_FAULTS, *FAULT_CLASSES.values()):
        parse_faults(spec)


@pytest.mark.parametrize("spec, words", [
    ("", "names no fault"),
    ("camera_freeze", "no '@time'"),
    ("melt@3", "unknown kind 'melt'"),
    ("camera_freeze@3", "needs a duration"),
    ("emergency@3+2", "takes no duration"),
    ("kill@3", "needs a node"),
    ("kill:sim_node@3", "needs a node"),
    ("occlude:tracker_node@3+1", "takes no node"),
    ("frame_drop@3+1,rate=1.5", "rate must be in (0, 0.99]"),
    ("frame_drop@3+1,rate=nan", "rate must be in"),
    ("kill:recorder@3,restart=maybe", "restart must be yes or no"),
    ("kill:recorder@3,rate=0.1", "option 'rate=0.1'"),
    ("occlude@-1+2", "finite and >= 0"),
    ("occlude@x+2", "is not AT[+DURATION]"),
    ("occlude@3+inf", "finite"),
])
def test_bad_specs_name_the_item_and_the_problem(spec, words):
    with pytest.raises(FaultSpecError) as err:
        parse_faults(spec)
    assert words in str(err.value)


def test_faults_need_their_nodes():
    check_against_graph(parse_faults("occlude@3+1;kill:bridge_node@4"), ["camera_sim", "bridge_node"])
    with pytest.raises(FaultSpecError, match="--no-vision"):
        check_against_graph(parse_faults("occlude@3+1"), ["sim_node", "planner_node"])
    with pytest.raises(FaultSpecError, match="--direct"):
        check_against_graph(parse_faults("unplug@3+1"), ["sim_node", "camera_sim"])
    with pytest.raises(FaultSpecError, match="tracker_node is not in this run"):
        check_against_graph(parse_faults("kill:tracker_node@3"), ["sim_node", "robot_emulator"])


def test_campaign_plan_is_the_full_product():
    plan = campaign_plan(["occlude@0+4", "emergency@0"], (0.2, 0.5), (1, 2, 3), ("line", "sine"),
                         {"line": 10.0, "sine": 20.0})
    assert len(plan) == 2 * 2 * 2 * 3
    assert {f.at for p, s, f in plan if p == "sine"} == {4.0, 10.0}
    assert all(f.duration == 4.0 for _, _, f in plan if f.kind == "occlude")


class _Watch:
    """The parts of the twin's watch node that fault_report reads, with nothing lost."""

    def __init__(self, obs):
        self.obs, self.seen, self.recorder_up = obs, {}, []

    def discovery_gaps(self):
        return {}


class _Injector:
    def __init__(self, done):
        self.done = done

    def failures(self):
        return []


def test_a_fault_timed_by_its_node_ends_its_duration_after_it_started():
    # occlude@3.1+4 (line, seed 1), planner started at 3.02 s: the injector's one action
    # covered the tag at 6.24 s, camera_sim's occluder took it away 4 s later, the tracker had the
    # tag again at 10.29 s, the planner said "odometry is stale" at 10.01 s and followed at 11.44 s
    start = 3.02
    status = [(2.86, 0)] + [(t, 1) for t in (4.29, 5.72, 7.15, 8.58)] + [(10.01, 3)] + [
        (t, 1) for t in (11.44, 12.87, 14.3)]
    obs = Observed(odom=[2.9 + 0.04 * i for i in range(98)] + [10.29 + 0.04 * i for i in range(100)],
                   status=status)
    f = Fault("occlude", 3.1, 4.0)
    report = fault_report([f], _Watch(obs), start, _Injector([(6.24, 0.0, f.label() + ": tag covered")]),
                          {}, PulseAges(0.5), True, None, [])
    assert report["per_fault"][0]["end_s"] == pytest.approx(6.24 + 4.0 - start)
    assert report["per_fault"][0]["recovery_s"] == pytest.approx(11.44 - 10.24)   # not 5.2 s from the cover
    # a fault its injector undoes ended when the undo ran; one with nothing run, at its nominal end
    freeze = Fault("camera_freeze", 3.1, 5.0)
    assert fault_end(freeze, 8.12, [6.2, 11.25]) == 11.25
    assert fault_end(freeze, 8.12, []) == 8.12
    assert fault_end(Fault("kill", 3.1, target="planner_node"), 6.12, [6.2]) == 6.2
    # wall-timed: a SIGSTOP whose SIGCONT never ran (the run ended) has only its start
    assert fault_end(Fault("sigstop", 3.1, 4.0, target="tracker_node"), 6.12, [6.2]) == 6.2


def test_recovery_time_and_outcome():
    status = [(t, 1) for t in (1, 2, 3)] + [(4, 3), (5, 3), (6, 3)] + [(7.5, 1), (9, 1)]
    assert recovery_time(status, 3.5, 6.2, 3.0) == pytest.approx(1.3)
    # blocked only after the fault's end (a kill shows when the pose goes stale): from the end
    assert recovery_time(status, 2.5, 2.5, 3.0) == pytest.approx(5.0)
    assert recovery_time(status, 0.5, 2.5, 1.0) == 0.0           # never blocked in its window
    assert recovery_time(status[:6], 3.5, 4.5, 3.0) is None       # blocked to the end
    assert recovery_time([(1, 1), (2, 2)], 1.5, 8.0, 3.0) == 0.0  # goal reached during the fault
    # a killed planner says nothing: the silence is the block, recovery its first status after
    dead = [(t, 1) for t in (1.0, 2.4, 3.9)] + [(9.5, 3), (10.9, 1), (12.3, 1)]
    assert recovery_time(dead, 4.0, 4.0, 3.0) == pytest.approx(6.9)
    assert outcome(True, None, 0, 0, []) == "completed"
    assert outcome(False, "emergency", 0, 0, []) == "stopped"
    assert outcome(True, None, 1, 0, []) == "failed"
    assert outcome(True, None, 0, 2, []) == "failed"
    assert outcome(False, "x", 0, 0, ["tracker_node"]) == "failed"


def test_recorder_losses_count_only_inside_the_up_intervals():
    seen = {"/a": [float(t) for t in range(20)]}
    recorded = {"/a": [t for t in range(20) if t not in (5, 12, 18)]}
    up = [(0.0, 10.0), (13.0, 19.5)]
    res = recorder_losses(seen, recorded, up, margin=1.0)["/a"]
    # 5 inside [1, 9], 12 is outside (down), 18 inside [14, 18.5]
    assert res["lost"] == 2 and res["first_lost"] == [5.0, 18.0]
    assert res["expected"] == len([t for t in range(20) if 1 <= t <= 9 or 14 <= t <= 18.5])
    assert not math.isnan(res["expected"])
    # a restarted publisher's first seconds are not the recorder's loss
    res = recorder_losses(seen, recorded, up, margin=1.0, excluded={"/a": [(17.5, 20.0)]})["/a"]
    assert res["lost"] == 1 and res["first_lost"] == [5.0]


def test_restart_windows_end_a_discovery_after_the_first_message_after_each_restart():
    assert restart_windows([10.43], [9.133, 13.833, 13.866], 3.0) == [(10.43, 13.833 + 3.0)]
    assert restart_windows([2.0, 10.0], [1.0, 2.5, 12.0], 3.0) == [(2.0, 5.5), (10.0, 15.0)]
    assert restart_windows([5.0], [1.0, 4.9], 3.0) == [(5.0, math.inf)]     # nothing after it: blind to the end
    assert restart_windows([], [1.0], 3.0) == []


def test_a_restarted_recorder_is_down_on_a_topic_until_a_new_subscription_of_it_appears():
    """Seen in a series of runs: the recorder restarted at 12.46 s subscribed to /frog/bridge/sent only
    after 17.164 s, when a message had been sent there; the window after the first message since the
    restart (restart_windows) had ended at 15.9 s, and the report called that message lost."""
    topics = ("/p", "/s")
    r = Resubscription(topics)
    r.seen(3.0, "/p", [(1,)])                   # the first recorder's endpoints
    r.seen(3.0, "/s", [(2,)])
    r.restarted(12.46)
    r.seen(12.6, "/p", [(1,)])                  # the killed recorder's endpoint, until its lease ends
    r.seen(12.6, "/s", [(2,)])
    r.restarted(13.0)                           # killed again before it subscribed: the first restart counts
    r.seen(16.0, "/p", [(1,), (3,)])            # the new one's, beside the stale one
    r.seen(17.5, "/s", [(4,)])
    r.seen(18.0, "/s", [(4,)])                  # no new endpoint: nothing changes
    assert r.gaps(3.0) == {"/p": [(12.46, 19.0)], "/s": [(12.46, 20.5)]}
    seen = {"/s": [12.88, 14.3, 17.164, 21.0, 24.0]}
    recorded = {"/s": [21.0]}
    excluded = r.gaps(3.0)
    assert recorder_losses(seen, recorded, [(3.0, 36.8)], excluded=excluded)["/s"]["first_lost"] == [24.0]
    # the old window alone would have called 17.164 lost
    old = {"/s": restart_windows([12.46], seen["/s"], 3.0)}
    assert 17.164 in recorder_losses(seen, recorded, [(3.0, 36.8)], excluded=old)["/s"]["first_lost"]
    r.restarted(30.0)                           # never subscribed again: down to the end
    assert r.gaps(3.0)["/p"][-1] == (30.0, math.inf)
