"""The tracker's states over a frame stream (no ROS): admission, frozen camera, state stamp, diagnostics."""

import pytest

from frog_vision.core.tracking_state import COASTING, FROZEN, LOST, SEARCHING, TRACKING, TrackingStates

DT = 1 / 30


def feed(t: TrackingStates, frames):
    """Frames as (stamp, bytes, seen, publishing); returns (verdict, state) per frame."""
    out = []
    for stamp, data, seen, publishing in frames:
        verdict, _ = t.admit(stamp, data)
        if verdict == "use":
            t.processed(stamp, seen=seen, publishing=publishing, coasting=publishing and not seen)
        out.append((verdict, t.state))
    return out


def test_searching_tracking_coasting_lost_and_the_state_stamp():
    t = TrackingStates()
    assert t.state_name == "waiting for images"
    seq = [(0.0, b"0", False, False), (DT, b"1", True, True), (2 * DT, b"2", True, True),
           (3 * DT, b"3", False, True), (4 * DT, b"4", False, True), (5 * DT, b"5", False, False)]
    assert [s for _, s in feed(t, seq)] == [SEARCHING, TRACKING, TRACKING, COASTING, COASTING, LOST]
    # the state stamp is the newest frame with the tag seen, through coasting and loss
    assert t.state_stamp == pytest.approx(2 * DT)
    assert t.state_age(1.0) == pytest.approx(1.0 - 2 * DT)
    level, message, values = t.report()
    assert level == 2 and "lost" in message and values["state"] == "lost" and values["frames"] == 6


def test_a_frozen_camera_is_refused_and_the_state_before_it_comes_back():
    t = TrackingStates(frozen_frames=3)
    feed(t, [(0.0, b"a", True, True)])
    verdicts = feed(t, [(DT, b"b", True, True), (2 * DT, b"b", True, True), (3 * DT, b"b", True, True),
                        (4 * DT, b"b", True, True), (5 * DT, b"c", True, True)])
    assert verdicts == [("use", TRACKING), ("skip", TRACKING), ("frozen", FROZEN), ("frozen", FROZEN),
                        ("use", TRACKING)]
    assert t.repeated_skipped == 1 and t.frozen.frozen_total == 2
    # nothing measured from the copies: the state stamp is the last real frame's
    assert t.state_stamp == pytest.approx(5 * DT)
    t2 = TrackingStates(frozen_frames=3)
    feed(t2, [(0.0, b"a", True, True), (DT, b"b", True, True)])
    changes = [t2.admit(k * DT, b"b")[1] for k in (2, 3)]
    assert changes[0] is None and changes[1].warn and "camera frozen" in changes[1].text
    assert t2.state_stamp == pytest.approx(DT)


def test_frames_that_do_not_advance_are_refused_once_logged():
    t = TrackingStates()
    feed(t, [(1.0, b"a", True, True)])
    assert t.admit(1.0, b"b")[0] == "skip" and t.admit(0.5, b"c")[0] == "skip"
    assert t.bad_frames == 2 and "not newer" in t.last_error
    assert t.error("same") and not t.error("same") and t.error("other")


def test_dropped_frames_are_estimated_from_the_gaps():
    t = TrackingStates()
    stamps = [k * DT for k in range(20)] + [k * DT for k in range(24, 30)]    # 4 frames missing
    feed(t, [(s, str(s).encode(), True, True) for s in stamps])
    assert t.dropped == 4
    assert t.frames == 26


def test_changes_are_reported_once():
    t = TrackingStates()
    t.admit(0.0, b"a")
    first = t.processed(0.0, seen=True, publishing=True)
    t.admit(DT, b"b")
    assert first.text == "tag tracking" and t.processed(DT, seen=True, publishing=True) is None
    t.admit(2 * DT, b"c")
    lost = t.processed(2 * DT, seen=False, publishing=False, reason="tag not found")
    assert lost.warn and lost.text == "tag lost (tag not found): odometry stopped"
