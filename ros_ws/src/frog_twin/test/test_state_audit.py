"""The audit of the state behind each pulse, on hand-built recordings (no ROS)."""

import math

import pytest

from frog_twin.core.state_audit import complete_intervals, measured_poses, pulse_ages


def _odom(t0, t1, rate=30.0, latency=0.04, offset=1000.0):
    """Odometry captured at each frame (stamp on the node clock), published ``latency`` later on the wall
    clock (``offset`` ahead of the node clock), received 5 ms after that."""
    n = int(round((t1 - t0) * rate))
    return [(t0 + k / rate, offset + t0 + k / rate + latency, offset + t0 + k / rate + latency + 0.005)
            for k in range(n)]


def _pulse(stamp, claim=0.1, offset=1000.0):
    """A pulse written at node time ``stamp``, published at once, received 7 ms later."""
    return (offset + stamp, offset + stamp + 0.007, claim, stamp)


def test_fresh_pulses_are_within_the_bound_and_the_age_is_from_the_newest_pose_before():
    odom = _odom(0.0, 10.0)
    ages = pulse_ages([_pulse(5.003), _pulse(5.083)], measured_poses(odom), bound_s=0.5)
    # the newest pose published before 5.003 s is the frame of 4.9333 s (published at 4.9733 s)
    assert ages.published[0] == pytest.approx(5.003 - 148 / 30, abs=1e-9)
    assert ages.stale() == [] and ages.summary()["pulses"] == 2


def test_a_pulse_after_the_tracker_died_is_stale_by_the_recording_whatever_the_bridge_claims():
    odom = _odom(0.0, 4.0)                               # the tracker killed at 4 s
    ages = pulse_ages([_pulse(3.5), _pulse(4.7), _pulse(6.0)], measured_poses(odom), bound_s=0.5)
    bad = ages.stale()
    assert [b["stamp"] for b in bad] == [4.7, 6.0]
    assert bad[1]["published"] == pytest.approx(6.0 - 119 / 30, abs=1e-9)
    # the bridge's own record alone also flags a pulse
    assert [b["stamp"] for b in pulse_ages([_pulse(3.5, 0.6)], measured_poses(odom), 0.5).stale()] == [3.5]


def test_predicted_poses_do_not_count_as_fresh():
    """The tag hidden from 2 s: the tracker coasts (odometry on, state stamp frozen at 2 s)."""
    odom = _odom(0.0, 4.0)
    states = {round(s, 6): (s if s < 2.0 else 1.99) for s, _, _ in odom}
    pulses = [_pulse(2.3), _pulse(2.7)]
    ages = pulse_ages(pulses, measured_poses(odom, states), bound_s=0.5)
    assert [b["stamp"] for b in ages.stale()] == [2.7]
    # without tracker states (the simulator's odometry) every pose is a measurement
    assert pulse_ages(pulses, measured_poses(odom), 0.5).stale() == []


def test_a_paused_world_is_no_age_and_a_pulse_before_any_pose_rests_on_nothing():
    """The world paused 3 s (wall) at 2 s: the node clock stood still, so a pulse written on its return
    rests on a fresh state, however much wall time passed."""
    odom = _odom(1.0, 2.0) + [(s, p + 3.0, r + 3.0) for s, p, r in _odom(2.0, 3.0)]
    pulses = [_pulse(0.5), (1000.0 + 2.0 + 3.05, 1000.0 + 2.0 + 3.06, 0.05, 2.05)]
    ages = pulse_ages(pulses, measured_poses(odom), 0.5)
    assert math.isinf(ages.published[0])
    assert ages.published[1] == pytest.approx(2.05 - 2.0, abs=1e-9)
    assert [b["stamp"] for b in ages.stale()] == [0.5]


def test_where_the_recording_is_incomplete_only_the_bridge_s_record_judges():
    """The recorder down from 4 to 8 s: no pose recorded, so the poses cannot judge the pulses then."""
    odom = _odom(0.0, 4.0) + _odom(8.0, 10.0)
    pulses = [_pulse(5.0), _pulse(6.0, 0.7), _pulse(9.0)]
    ages = pulse_ages(pulses, measured_poses(odom), 0.5)
    assert [b["stamp"] for b in ages.stale()] == [5.0, 6.0]
    ages.complete = [(0.0, 4.0), (8.5, 10.0)]
    assert [b["stamp"] for b in ages.stale()] == [6.0]                # the bridge's own record still judges
    assert ages.summary()["judged"] == 1


def test_receive_order_across_topics_is_reported_not_judged():
    """The recorder took the pulse off its queue before odometry published earlier: the receive
    reading says 5 s, the publish times say the state was fresh; only the latter judges."""
    odom = [(s, p, r + (5.0 if s > 3.0 else 0.0)) for s, p, r in _odom(0.0, 6.0)]
    ages = pulse_ages([_pulse(5.5)], measured_poses(odom), 0.5)
    assert ages.received[0] > 2.0 and ages.published[0] < 0.1 and ages.stale() == []


def test_the_recording_is_complete_while_the_recorder_is_up_and_has_matched_the_tracker():
    # recorder up 0-20 s and 25-40 s (1 s margins for its subscriptions); a restarted tracker
    # unmatched 8-11 s, and another 19-27 s over the recorder's restart
    assert complete_intervals([(0.0, 20.0), (25.0, 40.0)], [(8.0, 11.0), (19.0, 27.0)]) == \
        [(1.0, 8.0), (11.0, 19.0), (27.0, 40.0)]
    assert complete_intervals([(0.0, 0.5)], []) == []               # up for less than the margin
    assert complete_intervals([(0.0, 10.0)], [(-5.0, 20.0)]) == []  # a hole over all of it
    assert complete_intervals([(0.0, 10.0)], [(12.0, 14.0)]) == [(1.0, 10.0)]


def test_a_pulse_exactly_at_the_bound_is_not_stale_for_the_round_off_of_its_stamps():
    # a frame captured at 3.9 s, the pulse at 4.4 s: 4.4 - 3.9 = 0.5000000000000004 in floats, and the
    # bridge, which let it through at exactly 0.5 s, claims 0.5
    odom = [(3.9, 1000.0 + 3.9 + 0.04, 1000.0 + 3.9 + 0.045)]
    ages = pulse_ages([_pulse(4.4, claim=0.5)], measured_poses(odom), bound_s=0.5)
    assert ages.published[0] > 0.5 and ages.stale() == []
    # a microsecond and more past the bound is stale, by the recording and by the bridge's record
    late = pulse_ages([_pulse(4.40001, claim=0.5)], measured_poses(odom), bound_s=0.5)
    assert [b["stamp"] for b in late.stale()] == [4.40001]
    assert len(pulse_ages([_pulse(4.4, claim=0.50001)], measured_poses(odom), bound_s=0.5).stale()) == 1
