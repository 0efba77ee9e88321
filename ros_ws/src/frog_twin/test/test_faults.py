"""The fault spec, the campaign plan and the run metrics of frog_twin.core.faults (no ROS)."""

import math
from dataclasses import replace

import pytest

from frog_twin.core.faults import (
    CAMPAIGN_FAULTS, FAULT_CLASSES, Fault, FaultSpecError, Observed, Resubscription, campaign_plan, check_against_graph,
    content_time, fault_end, fault_report, outcome, parse_faults, recorder_losses, recovery_time, restart_windows,
    stale_firings)


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


def test_content_time_of_frozen_and_occluded_odometry():
    faults = [Fault("camera_freeze", 10.0, 5.0), Fault("occlude", 30.0, 2.0)]
    assert content_time(9.9, faults) == 9.9
    assert content_time(12.0, faults) == 10.0 and content_time(15.0, faults) == 10.0
    assert content_time(15.1, faults) == 15.1
    assert content_time(31.0, faults) == 30.0


def _observed(odom_until, decide_every=1.43, fire_delay=0.05, end=20.0):
    """Odometry at 30 Hz until ``odom_until``, a decision every period, a firing after each."""
    obs = Observed()
    obs.odom = [i / 30 for i in range(int(odom_until * 30))]
    t = 0.5
    while t < end:
        obs.decisions.append((t, "B"))
        obs.fired.append(t + fire_delay)
        t += decide_every
    return obs


def test_stale_firings_flag_decisions_on_old_state_and_old_commands():
    fresh = _observed(odom_until=20.0)
    assert stale_firings(fresh, [], pose_bound=3.0, command_bound=0.7) == []
    # odometry stops at 5 s and the planner goes on deciding: firings after 8 s are on stale state
    blind = _observed(odom_until=5.0)
    bad = stale_firings(blind, [], pose_bound=3.0, command_bound=0.7)
    assert bad and all(b["decided"] - 5.0 > 3.0 - 0.04 for b in bad)
    assert len(bad) == sum(1 for t, _ in blind.decisions if t - (5.0 - 1 / 30) > 3.0)
    # a frozen camera with fresh stamps is just as stale
    frozen = stale_firings(fresh, [Fault("camera_freeze", 5.0, 10.0)], 3.0, 0.7)
    assert frozen and all(8.0 < b["decided"] <= 15.0 for b in frozen)
    # a command replayed late
    late = _observed(odom_until=20.0, fire_delay=1.0)
    assert len(stale_firings(late, [], 3.0, 0.7)) == len(late.fired)
    # primitive I never fires anything: a firing with only I decided before it is flagged
    only_i = Observed(odom=[0.0, 1.0], decisions=[(0.5, "I")], fired=[0.6])
    assert stale_firings(only_i, [], 3.0, 0.7)[0]["why"] == "no primitive was decided before it"


def test_odometry_another_subscriber_saw_counts_and_only_what_existed():
    # the observer has no odometry from 5 s to 12 s (it had not matched a restarted tracker);
    # the recording has it: firings decided then are on fresh state
    fresh = _observed(odom_until=20.0)
    gap = replace(fresh, odom=[t for t in fresh.odom if not 5.0 < t < 12.0])
    assert stale_firings(gap, [], 3.0, 0.7)
    assert stale_firings(gap, [], 3.0, 0.7, witness_odom=fresh.odom) == []
    # a witness that also saw nothing there does not clear them
    also_gap = [t for t in fresh.odom if not 5.0 < t < 12.0]
    assert stale_firings(gap, [], 3.0, 0.7, witness_odom=also_gap) == stale_firings(gap, [], 3.0, 0.7)
    # what the witness saw of a frozen camera is still the frame at the freeze's start
    frozen = [Fault("camera_freeze", 5.0, 10.0)]
    assert stale_firings(gap, frozen, 3.0, 0.7, witness_odom=fresh.odom) == stale_firings(fresh, frozen, 3.0, 0.7)


class _Watch:
    """The parts of the twin's watch node that fault_report reads, with nothing lost or blind."""

    def __init__(self, obs):
        self.obs, self.seen, self.recorder_up = obs, {}, []

    def planner_blind(self):
        return []

    def odom_blind(self, witness_odom=()):
        return []

    def discovery_gaps(self):
        return {}


class _Injector:
    def __init__(self, done):
        self.done = done

    def failures(self):
        return []


def test_a_fault_timed_by_its_node_ends_its_duration_after_it_started():
    # campaign23 occlude@3.1+4 (line, seed 1), planner started at 3.02 s: the injector's one action
    # covered the tag at 6.24 s, camera_sim's occluder took it away 4 s later, the tracker had the
    # tag again at 10.29 s, the planner said "odometry is stale" at 10.01 s and followed at 11.44 s
    start = 3.02
    status = [(2.86, 0)] + [(t, 1) for t in (4.29, 5.72, 7.15, 8.58)] + [(10.01, 3)] + [
        (t, 1) for t in (11.44, 12.87, 14.3)]
    obs = Observed(odom=[2.9 + 0.04 * i for i in range(98)] + [10.29 + 0.04 * i for i in range(100)],
                   status=status)
    f = Fault("occlude", 3.1, 4.0)
    report = fault_report([f], _Watch(obs), start, _Injector([(6.24, 0.0, f.label() + ": tag covered")]),
                          {}, 3.56, 0.7, True, None, [])
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


def test_old_command_verdicts_inside_a_blind_interval_are_unverified_not_stale():
    obs = Observed(odom=[i / 30 for i in range(600)], decisions=[(1.0, "B"), (9.0, "B")],
                   fired=[1.05, 6.0, 9.05])
    bad = stale_firings(obs, [], 3.0, 0.7, blind=[(4.0, 7.0)])
    assert [(b["fired"], b["unverified"]) for b in bad] == [(6.0, True)]
    bad = stale_firings(obs, [], 3.0, 0.7)
    assert [(b["fired"], b["unverified"]) for b in bad] == [(6.0, False)]
    # the recording saw the restarted planner's decision behind it: verified, and fresh
    assert stale_firings(obs, [], 3.0, 0.7, blind=[(4.0, 7.0)], witness_decisions=[(5.98, "C")]) == []
    # it saw an I there (which fires nothing): the firing is still the 5 s old command's
    bad = stale_firings(obs, [], 3.0, 0.7, witness_decisions=[(5.98, "I")])
    assert [(b["fired"], b["decided"]) for b in bad] == [(6.0, 1.0)]


def test_restart_windows_end_a_discovery_after_the_first_message_after_each_restart():
    assert restart_windows([10.43], [9.133, 13.833, 13.866], 3.0) == [(10.43, 13.833 + 3.0)]
    assert restart_windows([2.0, 10.0], [1.0, 2.5, 12.0], 3.0) == [(2.0, 5.5), (10.0, 15.0)]
    assert restart_windows([5.0], [1.0, 4.9], 3.0) == [(5.0, math.inf)]     # nothing after it: blind to the end
    assert restart_windows([], [1.0], 3.0) == []


def test_a_restarted_recorder_is_down_on_a_topic_until_a_new_subscription_of_it_appears():
    """Session 31's series: the recorder restarted at 12.46 s subscribed to /frog/bridge/sent only
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


def test_a_pose_no_witness_saw_after_a_tracker_restart_is_unverified_only_as_the_planner_reports_it():
    """The campaign's kill:tracker_node@7.1 (line, seed 1): odometry seen by the watch and the recording
    until 9.13 s, the restarted tracker's from 13.83 s; the planner matched it earlier and decided at
    12.87 s on a pose it reports 0.037 s old. Without a restart, or with the planner itself reporting
    an old pose, the same firing is stale."""
    odom = [i / 30 for i in range(274)] + [13.833 + i / 30 for i in range(150)]
    obs = Observed(odom=odom, decisions=[(11.44, "B"), (12.87, "B")], fired=[11.45, 12.88, 12.96])
    stale = stale_firings(obs, [], 3.56, 0.7)
    assert [b["fired"] for b in stale] == [12.88, 12.96] and not any(b["unverified"] for b in stale)
    blind = [(10.43, 13.833 + 3.0)]
    ok = {12.87: 0.037, 11.44: 2.307}
    bad = stale_firings(obs, [], 3.56, 0.7, odom_blind=blind, reported_pose_age=ok)
    assert [(b["fired"], b["unverified"]) for b in bad] == [(12.88, True), (12.96, True)]
    # the planner reports the old pose itself: stale, restart or not
    old = {12.87: 3.74}
    assert not any(b["unverified"] for b in stale_firings(obs, [], 3.56, 0.7, odom_blind=blind,
                                                           reported_pose_age=old))
    # no status for the decision, or a decision outside the restart's window: stale
    assert not any(b["unverified"] for b in stale_firings(obs, [], 3.56, 0.7, odom_blind=blind))
    assert not any(b["unverified"] for b in stale_firings(obs, [], 3.56, 0.7, odom_blind=[(1.0, 5.0)],
                                                           reported_pose_age=ok))
    # a command that fires late is stale whatever the planner says of its pose
    late = Observed(odom=odom, decisions=[(12.87, "B")], fired=[14.0])
    assert not any(b["unverified"] for b in stale_firings(late, [], 3.56, 0.7, odom_blind=blind,
                                                           reported_pose_age=ok))


def test_a_firing_stamped_just_before_its_decision_is_that_decision_s():
    """Node clocks under /clock differ by ms: a firing 10 ms 'before' its decision is not the previous one's."""
    obs = Observed(odom=[i / 30 for i in range(300)], decisions=[(1.0, "B"), (2.43, "B")], fired=[1.02, 2.42])
    assert stale_firings(obs, [], 3.0, 0.7) == []
    obs.fired.append(2.3)      # 130 ms before: a firing of the first decision, 1.3 s old
    assert [b["fired"] for b in stale_firings(obs, [], 3.0, 0.7)] == [2.3]


def test_arrival_order_attributes_a_firing_stamped_well_before_its_decision():
    """Under load the robot's clock can trail the planner's by 250 ms (seen in the campaign): the
    arrival order at the observer is causal, the stamps are not."""
    obs = Observed(odom=[i / 30 for i in range(900)], decisions=[(14.3, "B"), (18.59, "D")], fired=[14.3, 18.34],
                   decision_seq=[1, 3], fired_seq=[2, 4])
    assert stale_firings(obs, [], 3.0, 0.7) == []
    # the same stamps ordered by stamps alone would blame the 4 s old decision
    no_order = Observed(odom=obs.odom, decisions=obs.decisions, fired=obs.fired)
    assert [b["fired"] for b in stale_firings(no_order, [], 3.0, 0.7)] == [18.34]
    # a firing that really arrives after a long silence of the planner is still stale
    late = Observed(odom=obs.odom, decisions=[(14.3, "B")], fired=[14.3, 18.34], decision_seq=[1], fired_seq=[2, 3])
    assert [b["fired"] for b in stale_firings(late, [], 3.0, 0.7)] == [18.34]


def test_a_firing_taken_off_the_queue_before_its_decision_is_still_that_decision_s():
    """A CI run: the observer handled the bridge's sent (15.754) before the planner's primitive
    (15.734) that caused it, both ready in one wait set; by arrival alone the firing was the
    1.45 s old decision's. The newer of the stamp and the arrival readings is its cause."""
    obs = Observed(odom=[i / 30 for i in range(900)], decisions=[(14.3, "E"), (15.734, "E")],
                   fired=[14.3, 15.754, 15.838], decision_seq=[1, 4], fired_seq=[2, 3, 5])
    assert stale_firings(obs, [], 3.0, 0.7) == []
    # a command really fired long after its decision is still caught, whatever the order
    old = Observed(odom=obs.odom, decisions=[(14.3, "E")], fired=[14.3, 15.754], decision_seq=[1], fired_seq=[2, 3])
    assert [b["fired"] for b in stale_firings(old, [], 3.0, 0.7)] == [15.754]
