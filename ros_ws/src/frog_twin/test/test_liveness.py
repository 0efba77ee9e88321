"""The deaf-tracker check on hand-made diagnostics sequences (1 Hz, as the nodes publish them)."""

import pytest

from frog_twin.core.liveness import ClockWatch, DeafWatch, RecorderWatch, tracker_stuck


def feed(w, t0, t1, camera_rate, tracker_rate, cam0=0, trk0=0, tracker_reports=True, excused=lambda t: False):
    """Diagnostics every second from t0 to t1; the first time deaf_for() answered, or None."""
    for k in range(int(t1 - t0) + 1):
        t = t0 + k
        w.camera(t, cam0 + int(camera_rate * (t - t0)))
        if tracker_reports:
            w.tracker(t + 0.3, trk0 + int(tracker_rate * (t - t0)))
        d = w.deaf_for(t + 0.5, excused(t))
        if d is not None:
            return t + 0.5, d
    return None


def test_a_tracker_that_hears_is_never_deaf():
    assert feed(DeafWatch(8.0, 10), 0, 60, 30, 30) is None
    assert feed(DeafWatch(8.0, 10), 0, 60, 30, 2) is None          # slow (loaded machine) but hearing


def test_a_tracker_whose_count_stalls_is_deaf_after_the_bound():
    w = DeafWatch(8.0, 10)
    assert feed(w, 0, 10, 30, 30) is None
    # from t = 11 the camera goes on (30 frames/s) and the tracker's count stays where it was
    t, d = feed(w, 11, 40, 30, 0, cam0=330, trk0=300)
    assert d >= 8.0 and t - d == pytest.approx(10.3)     # silent since its last new count (t = 10.3)


def test_a_tracker_whose_diagnostics_stop_is_deaf_too():
    w = DeafWatch(8.0, 10)
    feed(w, 0, 5, 30, 30)
    t, d = feed(w, 6, 40, 30, 0, cam0=180, tracker_reports=False)
    assert t == pytest.approx(13.5) and d == pytest.approx(8.2)


def test_a_stalled_camera_makes_no_deaf_tracker():
    w = DeafWatch(8.0, 10)
    feed(w, 0, 5, 30, 30)
    assert feed(w, 6, 40, 0, 0, cam0=150, trk0=150) is None      # clock stall, camera stopped: no frames
    assert feed(w, 41, 80, 0.2, 0, cam0=150, trk0=150) is None    # fewer than min_frames in the silence


def test_excused_silence_does_not_count_and_the_wait_restarts_after_it():
    w = DeafWatch(8.0, 10)
    feed(w, 0, 5, 30, 30)
    # the tracker SIGSTOPped on purpose from 6 to 26 s: excused; deaf 8 s after the excuse ends
    t, d = feed(w, 6, 60, 30, 0, cam0=180, trk0=150, excused=lambda t: t <= 26)
    assert t == pytest.approx(34.5) and d == pytest.approx(8.0)


def test_a_new_tracker_process_counts_as_hearing():
    w = DeafWatch(8.0, 10)
    feed(w, 0, 5, 30, 30)
    w.camera(6, 200)
    w.tracker(6.3, 0)             # a restarted tracker reports a smaller count
    assert w.deaf_for(6.5, False) is None and w.published == 0


@pytest.mark.parametrize("says, frames, stuck", [
    ("tracking", 30, True),                                   # it never said the tag was lost
    ("tag not seen: coasting on the prediction", 30, True),   # coasting ends in tracking or "tag lost" within 0.5 s
    (None, 30, True),                                         # it never said anything
    ("tag lost: odometry stopped", 30, False),                # a working tracker that lost the tag
    ("camera frozen: 3 identical frames in a row; odometry stopped", 30, False),
    ("searching", 30, False),                                 # restarted, never found the tag
    ("tracking", 9, False),                                   # the camera itself (nearly) stopped
])
def test_a_real_tracker_is_stuck_only_if_it_never_said_the_tag_was_lost(says, frames, stuck):
    assert tracker_stuck(frames, says, min_frames=10) is stuck


@pytest.mark.parametrize("says, said_at, stuck", [
    ("searching", 10.0, True),                     # restarted, then a pose: it was tracking when it stopped
    ("tag lost: odometry stopped", 12.5, False),   # it lost the tag after that pose and said so
    ("searching", None, False),                    # no time known: the word stands
])
def test_a_pose_after_the_last_word_says_tracking(says, said_at, stuck):
    assert tracker_stuck(30, says, min_frames=10, said_at=said_at, last_pose_at=12.0) is stuck


def test_bad_settings_are_refused():
    with pytest.raises(ValueError, match="bound_s"):
        DeafWatch(0.0, 10)
    with pytest.raises(ValueError, match="min_frames"):
        DeafWatch(8.0, 0)
    with pytest.raises(ValueError, match="bound_s"):
        ClockWatch(0.0)


def test_the_twin_refuses_a_negative_bound(capsys):
    from frog_twin.twin import _main
    with pytest.raises(SystemExit) as exc:
        _main(["--deaf-tracker-after", "-1"])
    assert exc.value.code == 2
    assert "--deaf-tracker-after must be >= 0 (0 = off)" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        _main(["--deaf-recorder-after", "-1"])
    assert exc.value.code == 2
    assert "--deaf-recorder-after must be >= 0 (0 = off)" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        _main(["--world-stall-after", "nan"])
    assert exc.value.code == 2
    assert "--world-stall-after must be >= 0 (0 = off)" in capsys.readouterr().err


def test_a_running_clock_never_stalls():
    watch = ClockWatch(bound_s=5.0)
    assert all(watch.stalled_for(t, 100.0 + 0.5 * t, False) is None for t in range(60))


def test_a_clock_that_stops_is_stalled_after_the_bound_and_stays_so():
    watch = ClockWatch(bound_s=5.0)
    for t in range(10):                       # runs, then stops at 104.5 s simulated (t = 9)
        assert watch.stalled_for(t, 100.0 + 0.5 * t, False) is None
    assert watch.stalled_for(13.9, 104.5, False) is None
    assert watch.stalled_for(14.0, 104.5, False) == pytest.approx(5.0)
    assert watch.stalled_for(30.0, 104.5, False) == pytest.approx(21.0)
    assert watch.stalled_for(30.1, 104.6, False) is None      # it moves again


def test_a_pause_on_purpose_is_excused_and_the_wait_restarts_after_it():
    watch = ClockWatch(bound_s=5.0)
    watch.stalled_for(0.0, 10.0, False)
    for t in range(1, 30):                     # paused by the injector for 29 s
        assert watch.stalled_for(float(t), 10.0, True) is None
    assert watch.stalled_for(33.9, 10.0, False) is None        # 4.9 s after the excuse ended
    assert watch.stalled_for(34.0, 10.0, False) == pytest.approx(5.0)


def test_a_clock_seen_once_has_not_stalled_yet():
    watch = ClockWatch(bound_s=5.0)
    assert watch.stalled_for(0.0, None, False) is None
    assert watch.stalled_for(100.0, None, False) is None      # no /clock yet: not this check's case
    assert watch.stalled_for(101.0, 3.0, False) is None
    assert watch.stalled_for(105.9, 3.0, False) is None
    assert watch.stalled_for(106.0, 3.0, False) == pytest.approx(5.0)


TOPICS = ("/frog/primitive", "/frog/planner/status", "/frog/bridge/sent", "/frog/limb_activation")


def run_recorder(w, t1, recorded_rate, period=1.43, wedged_from=None, wedged=(), reported=TOPICS):
    """A planner deciding every ``period`` s (a primitive and a status each time, a firing on sent and
    limb_activation every other one), the watch seeing all; the recorder's diagnostics every second
    (stamped on the same clock) with its counts, which stop rising on ``wedged`` topics from
    ``wedged_from``. The first answer of deaf_for(), or None."""
    rec = dict.fromkeys(reported, 0)
    for t in range(int(t1) + 1):
        decisions = int(t / period)
        seen = {TOPICS[0]: decisions, TOPICS[1]: decisions, TOPICS[2]: decisions // 2, TOPICS[3]: decisions // 2}
        w.published(t, seen)
        for topic in reported:
            if not (wedged_from is not None and t >= wedged_from and topic in wedged):
                rec[topic] = int(seen[topic] * recorded_rate)
        w.recorded(t + 0.3, float(t), dict(rec))
        d = w.deaf_for(t + 0.5, False)
        if d is not None:
            return t + 0.5, d
    return None


def test_a_recorder_that_records_is_never_deaf():
    assert run_recorder(RecorderWatch(TOPICS, 8.0), 120, 1.0) is None


def test_a_recorder_that_stops_recording_one_topic_is_deaf_on_it_after_the_bound():
    """Session 29's restarted recorder: subscribed, recording nothing on the planner's topics."""
    w = RecorderWatch(TOPICS, 8.0)
    when, (topic, silent, published) = run_recorder(w, 120, 1.0, wedged_from=30, wedged=(TOPICS[0],))
    assert topic == TOPICS[0] and 8.0 <= silent < 10.0 and published >= 5
    # deaf from the diagnostics of its last rise: the last second before 30 s with a new decision
    last_rise = max(t for t in range(1, 30) if int(t / 1.43) > int((t - 1) / 1.43))
    assert w.heard_at[TOPICS[0]] == last_rise == 29.0 and 36.0 <= when <= 40.0
    assert w.heard_at[TOPICS[1]] > 35.0                 # the others were recorded meanwhile


def test_a_topic_the_recorder_never_reports_is_deaf_once_published():
    when, (topic, _, _) = run_recorder(RecorderWatch(TOPICS, 8.0), 60, 1.0, reported=TOPICS[:3])
    assert topic == TOPICS[3] and when < 20


def test_a_quiet_topic_is_not_deaf_and_a_new_recorder_process_counts_as_recording():
    w = RecorderWatch(TOPICS, 8.0)
    for t in range(60):                  # the planner publishes I: nothing on sent / limb_activation
        w.published(t, {TOPICS[0]: t, TOPICS[1]: t, TOPICS[2]: 0, TOPICS[3]: 0})
        # a restarted recorder at 30 s: its counts start again from 0
        w.recorded(t + 0.3, float(t), {TOPICS[0]: t if t < 30 else t - 30, TOPICS[1]: t if t < 30 else t - 30,
                                       TOPICS[2]: 0, TOPICS[3]: 0})
        assert w.deaf_for(t + 0.5, False) is None, t
    assert w.heard_at[TOPICS[0]] == 59.0 and w.heard_at[TOPICS[2]] is None


def test_a_new_recorder_process_that_records_nothing_has_heard_nothing():
    """Session 29: the recorder restarted after a kill reports 0 on the planner's topics: its deaf time
    starts where it subscribed (heard_at None), not at its first diagnostics."""
    w = RecorderWatch(TOPICS, 8.0)
    w.recorded(0.3, 10.0, {TOPICS[0]: 7})
    w.recorded(1.3, 11.0, {TOPICS[0]: 8})
    assert w.heard_at[TOPICS[0]] == 11.0
    w.recorded(5.3, 15.0, {TOPICS[0]: 0})          # the restarted process
    assert w.heard_at[TOPICS[0]] is None
    w.recorded(6.3, 16.0, {TOPICS[0]: 0})
    assert w.heard_at[TOPICS[0]] is None
    w.recorded(7.3, 17.0, {TOPICS[0]: 2})
    assert w.heard_at[TOPICS[0]] == 17.0
    w.recorded(9.3, 19.0, {TOPICS[0]: 1})          # restarted again, and it recorded one already
    assert w.heard_at[TOPICS[0]] == 19.0


def test_a_topic_the_restarted_recorder_has_not_subscribed_to_yet_is_not_deaf_until_it_has():
    """Session 31: a restarted recorder subscribed to /frog/primitive 5 s after its restart; the graph
    still showed the killed one's subscription, so the wait had started at the restart and the new
    recorder was killed for deaf 3.5 s after it subscribed. Excused on that topic, its wait starts at
    the subscription: with nothing recorded it is deaf a bound after that, not before."""
    w = RecorderWatch(TOPICS, 6.0)
    subscribed_at = 12
    found = None
    for t in range(40):
        decisions = int(t / 1.43)
        w.published(t, {TOPICS[0]: decisions})
        w.recorded(t + 0.3, float(t), {TOPICS[0]: 0})     # a new process that records nothing
        d = w.deaf_for(t + 0.5, False, excused_topics={TOPICS[0]} if t < subscribed_at else set())
        if d is not None:
            found = (t + 0.5, d)
            break
    assert found is not None and found[1][0] == TOPICS[0]
    # the last excused poll (11.5 s) starts the wait
    assert subscribed_at - 0.5 + 6.0 <= found[0] < subscribed_at + 8.0, found
    # not excused: the same recorder is deaf 6 s after the start of the watch
    w = RecorderWatch(TOPICS, 6.0)
    for t in range(40):
        w.published(t, {TOPICS[0]: int(t / 1.43)})
        w.recorded(t + 0.3, float(t), {TOPICS[0]: 0})
        if w.deaf_for(t + 0.5, False) is not None:
            assert t + 0.5 < subscribed_at
            break
