"""The audit of the state behind each pulse, on hand-built recordings (no ROS)."""

import math

import pytest

from frog_twin.core.state_audit import measured_poses, pulse_ages


def _odom(t0, t1, rate=30.0, latency=0.04):
    """Odometry stamped at each frame, published ``latency`` later, received 5 ms after that."""
    n = int(round((t1 - t0) * rate))
    return [(t0 + k / rate, t0 + k / rate + latency, t0 + k / rate + latency + 0.005) for k in range(n)]


def test_fresh_pulses_are_within_the_bound_and_the_age_is_from_the_newest_pose_before():
    odom = _odom(0.0, 10.0)
    pulses = [(5.0 + 0.003, 5.01, 0.09, 5.0), (5.083, 5.09, 0.17, 5.08)]        # front, rear one pulse later
    ages = pulse_ages(pulses, measured_poses(odom), bound_s=0.5)
    # the newest pose published before 5.003 s is the frame of 4.9333 s, published at 4.9733 s
    assert ages.published[0] == pytest.approx(5.003 - (4.93333 + 0.04), abs=1e-4)
    assert ages.stale() == [] and ages.summary()["pulses"] == 2


def test_a_pulse_after_the_tracker_died_is_stale_by_the_recording_whatever_the_bridge_claims():
    odom = _odom(0.0, 4.0)                               # the tracker killed at 4 s
    pulses = [(3.5, 3.51, 0.1, 3.5), (4.7, 4.71, 0.1, 4.7), (6.0, 6.01, 0.1, 6.0)]
    ages = pulse_ages(pulses, measured_poses(odom), bound_s=0.5)
    bad = ages.stale()
    assert [b["t"] for b in bad] == [4.7, 6.0]
    assert bad[1]["published"] == pytest.approx(6.0 - (3.96667 + 0.04), abs=1e-4)
    # the bridge's own record alone also flags a pulse
    assert [b["t"] for b in pulse_ages([(3.5, 3.51, 0.6, 3.5)], measured_poses(odom), 0.5).stale()] == [3.5]


def test_predicted_poses_do_not_count_as_fresh():
    """The tag hidden from 2 s: the tracker coasts (odometry on, state stamp frozen at 2 s)."""
    odom = _odom(0.0, 4.0)
    states = {round(s, 6): (s if s < 2.0 else 1.99) for s, _, _ in odom}
    pulses = [(2.3, 2.31, 0.1, 2.3), (2.7, 2.71, 0.1, 2.7)]
    ages = pulse_ages(pulses, measured_poses(odom, states), bound_s=0.5)
    assert [b["t"] for b in ages.stale()] == [2.7]
    # without tracker states (the simulator's odometry) every pose is a measurement
    assert pulse_ages(pulses, measured_poses(odom), 0.5).stale() == []


def test_ages_scale_to_simulated_time_and_a_pulse_before_any_pose_rests_on_nothing():
    odom = _odom(1.0, 3.0)
    ages = pulse_ages([(0.5, 0.51, 0.0, 0.5), (2.5, 2.51, 0.0, 2.5)], measured_poses(odom), 0.5, real_time_factor=2.0)
    assert math.isinf(ages.published[0])
    # the newest frame published by 2.5 s is 2.4333 s (published 2.4733 s): 0.0267 s wall, 0.0533 s simulated
    assert ages.published[1] == pytest.approx(2.0 * (2.5 - (1.0 + 43 / 30 + 0.04)), abs=1e-6)
    assert len(ages.stale()) == 1


def test_where_the_recording_is_incomplete_only_the_bridge_s_record_judges():
    """The recorder down from 4 to 8 s: no pose recorded, so the poses cannot judge the pulses then."""
    odom = _odom(0.0, 4.0) + _odom(8.0, 10.0)
    pulses = [(5.0, 5.01, 0.1, 5.0), (6.0, 6.01, 0.7, 6.0), (9.0, 9.01, 0.1, 9.0)]
    ages = pulse_ages(pulses, measured_poses(odom), 0.5)
    assert [b["t"] for b in ages.stale()] == [5.0, 6.0]
    ages.complete = [(0.0, 4.0), (8.5, 10.0)]
    assert [b["t"] for b in ages.stale()] == [6.0]                # the bridge's own record still judges
    assert ages.summary()["judged"] == 1
