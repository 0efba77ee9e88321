"""Run metrics against hand-made trajectories whose figures are known by construction of geometry."""

import math

import numpy as np
import pytest

from frog_twin.core.metrics import (best_window_rate, distance_to_polyline, latency_stats, pose_errors,
                                   tracking_metrics)


def test_distance_to_a_polyline_is_geometry():
    path = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]])
    pts = np.array([[0.5, 0.2], [1.3, 0.5], [-0.3, -0.4], [2.0, 2.0], [0.9, 0.05]])
    expected = [0.2, 0.3, 0.5, math.hypot(1.0, 1.0), 0.05]
    assert distance_to_polyline(pts, path) == pytest.approx(expected, abs=1e-12)


def test_tracking_metrics_of_a_constant_offset_run():
    """2 cm left of a 0.6 m line at 2 cm/s, goal at t = 30 s: mean = max = 2 cm, 2 cm/s."""
    path = np.c_[np.linspace(0, 0.6, 100), np.zeros(100)]
    t = np.linspace(0.0, 40.0, 801)
    xy = np.c_[np.minimum(0.02 * t, 0.65), np.full_like(t, 0.02)]
    prims = ["B"] * 20 + ["I"]
    m = tracking_metrics(t, xy, path, goal_time=30.0, primitives=prims)
    assert m["mean_distance_m"] == pytest.approx(0.02, abs=1e-9)
    assert m["max_distance_m"] == pytest.approx(0.02, abs=1e-9)
    assert m["completion_time_s"] == pytest.approx(30.0)
    assert m["mean_speed_along_path_m_per_s"] == pytest.approx(0.6 / 30.0)
    assert m["primitives_used"] == {"B": 20}


def test_tracking_metrics_without_goal_and_a_growing_error():
    """Drifting away linearly: y = 0.001 t for 10 s -> mean 5 mm, max 10 mm, half-way progress."""
    path = np.c_[np.linspace(0, 0.2, 50), np.zeros(50)]
    t = np.linspace(0.0, 10.0, 1001)
    xy = np.c_[0.01 * t, 0.001 * t]
    m = tracking_metrics(t, xy, path)
    assert m["completion_time_s"] is None
    assert m["mean_distance_m"] == pytest.approx(0.005, rel=1e-3)
    assert m["max_distance_m"] == pytest.approx(0.010, rel=1e-9)
    assert m["final_progress"] == pytest.approx(0.5, rel=1e-9)
    assert m["mean_speed_along_path_m_per_s"] == pytest.approx(0.01, rel=1e-9)


def test_pose_errors_interpolate_the_truth_and_wrap_headings():
    tt = np.linspace(0, 10, 101)
    truth = np.c_[0.01 * tt, np.zeros_like(tt), np.pi - 0.05 + 0.01 * tt]   # heading crosses +pi
    te = np.array([1.05, 5.0, 9.95, 20.0])                                   # the last is outside
    est = np.c_[0.01 * te + 0.001, np.full(4, 0.002), (np.pi - 0.05 + 0.01 * te + 0.02 + np.pi) % (2 * np.pi) - np.pi]
    e = pose_errors(te, est, tt, truth)
    assert e["n"] == 3
    assert e["position_mean_m"] == pytest.approx(math.hypot(0.001, 0.002), rel=1e-9)
    assert e["heading_max_rad"] == pytest.approx(0.02, abs=1e-9)


def test_latency_pairs_each_firing_with_the_latest_send():
    sent = [0.0, 1.5, 3.0]
    fired = [0.030, 1.545, 3.020, 3.100]
    lat = latency_stats(sent, fired)
    assert lat["n"] == 4
    assert lat["median_s"] == pytest.approx(np.median([0.03, 0.045, 0.02, 0.1]))
    assert lat["max_s"] == pytest.approx(0.1)


# ------------------------------------------------------------------ signed lateral offset, finish time
def _circle(radius, n=400, turns=0.9, ccw=True):
    a = np.linspace(0.0, 2 * np.pi * turns, n)
    return np.c_[radius * np.cos(a), (1 if ccw else -1) * radius * np.sin(a)], a


@pytest.mark.parametrize("side", [+1, -1])
def test_signed_lateral_offset_on_a_straight_path(side):
    """2 cm to the left of a line along +x gives +0.02 m, to the right -0.02 m; any heading of the line."""
    from frog_twin.core.metrics import signed_lateral_offset
    for heading in (0.0, 1.0, 2.5, -2.0):
        c, s = math.cos(heading), math.sin(heading)
        path = np.c_[np.linspace(0, 0.5, 60) * c, np.linspace(0, 0.5, 60) * s]
        u = np.linspace(0.01, 0.49, 37)
        left = np.array([-s, c])
        pts = np.c_[u * c, u * s] + side * 0.02 * left
        assert signed_lateral_offset(pts, path) == pytest.approx(np.full(len(u), side * 0.02), abs=1e-12)
        m = tracking_metrics(np.linspace(0, 10, len(u)), pts, path)
        assert m["mean_signed_lateral_m"] == pytest.approx(side * 0.02, abs=1e-12)
        assert m["mean_distance_m"] == pytest.approx(0.02, abs=1e-12)


@pytest.mark.parametrize("ccw", [True, False])
def test_signed_lateral_offset_on_a_circle(ccw):
    """On a counter-clockwise circle the inside is left (+), on a clockwise one right (-)."""
    from frog_twin.core.metrics import signed_lateral_offset
    radius = 0.14
    path, _ = _circle(radius, ccw=ccw)
    inner, _ = _circle(radius - 0.02, n=97, turns=0.85, ccw=ccw)
    outer, _ = _circle(radius + 0.02, n=97, turns=0.85, ccw=ccw)
    sag = radius * (1 - math.cos(np.pi * 0.9 / 399))      # the polyline's chord error
    sign = 1.0 if ccw else -1.0
    assert signed_lateral_offset(inner, path) == pytest.approx(np.full(97, sign * 0.02), abs=sag + 1e-9)
    assert signed_lateral_offset(outer, path) == pytest.approx(np.full(97, -sign * 0.02), abs=sag + 1e-9)
    t = np.linspace(0, 20, 97)
    m = tracking_metrics(t, outer, path)
    assert m["mean_signed_lateral_m"] == pytest.approx(-sign * 0.02, abs=sag + 1e-9)
    assert m["mean_distance_m"] == pytest.approx(0.02, abs=sag + 1e-9)


def test_signed_lateral_offset_of_a_swing_averages_out():
    """Equal swings to both sides: mean distance 1 cm (|sin| mean 2/pi * amplitude), signed mean 0."""
    path = np.c_[np.linspace(0, 1.0, 200), np.zeros(200)]
    x = np.linspace(0.0, 1.0, 4001)[:-1]
    y = 0.01 * np.pi / 2 * np.sin(2 * np.pi * 4 * x)
    m = tracking_metrics(np.linspace(0, 40, len(x)), np.c_[x, y], path)
    assert m["mean_signed_lateral_m"] == pytest.approx(0.0, abs=1e-6)
    assert m["mean_distance_m"] == pytest.approx(0.01, rel=1e-3)


def test_finish_time_within_tolerance_or_past_the_finish_line():
    from frog_twin.core.metrics import finish_time
    path = np.c_[np.linspace(0, 0.4, 100), np.zeros(100)]
    t = np.linspace(0.0, 45.0, 451)                        # 0.1 s steps, 1 cm/s
    on_path = np.c_[0.01 * t, np.zeros_like(t)]
    assert finish_time(t, on_path, path, goal_tolerance=0.0351) == pytest.approx(36.5)   # 3.5 cm before the end
    wide = np.c_[0.01 * t, np.full_like(t, 0.05)]          # 5 cm to the side: finishes past the finish line
    assert finish_time(t, wide, path, goal_tolerance=0.03) == pytest.approx(40.1)
    short = np.c_[0.005 * t, np.zeros_like(t)]             # not even at the end after 45 s
    assert finish_time(t, short, path) is None


def test_the_finish_of_a_path_that_ends_near_its_start():
    """An ellipse whose end is 2.8 cm from its start (the hardware runs' ellipses, tolerance 3 cm):
    the start is not the finish, and a robot that passes the end 4 cm outside it has finished
    there (past the normal at the end), whatever comes after; 12 cm outside, a 10 cm finish line
    does not count it."""
    from frog_twin.core.metrics import finish_time, samples_before_finish
    a = np.linspace(0.0, 2 * np.pi - 0.2, 100)              # end 0.2 rad short of the start: 2.8 cm on r = 0.14
    path = np.c_[0.14 * np.cos(a), 0.14 * np.sin(a)]
    assert math.hypot(*(path[0] - path[-1])) == pytest.approx(2 * 0.14 * math.sin(0.1), rel=1e-9)
    t = np.linspace(0.0, 60.0, 601)
    ang = np.linspace(0.0, 2 * np.pi + 0.5, 601)            # goes round and on, 0.3 rad past the end
    for offset, band, finished in ((0.04, None, True), (0.04, 0.10, True), (0.12, 0.10, False)):
        r = 0.14 + offset
        xy = np.c_[r * np.cos(ang), r * np.sin(ang)]
        # first sample past the finish line: the normal through the end to the path's last segment
        # (on the way round: the start, too, lies beyond that line)
        k_end = int(np.argmax((ang > np.pi) & ((xy - path[-1]) @ (path[-1] - path[-2]) > 0.0)))
        assert abs(ang[k_end] - (2 * np.pi - 0.2)) < 0.03
        got = finish_time(t, xy, path, goal_tolerance=0.03, lateral_tolerance=band)
        assert (got == pytest.approx(t[k_end])) if finished else got is None, (offset, band, got)
    xy = np.c_[0.18 * np.cos(ang), 0.18 * np.sin(ang)]
    past = (ang > np.pi) & ((xy - path[-1]) @ (path[-1] - path[-2]) > 0)
    assert samples_before_finish(xy, path) == int(np.argmax(past))
    # standing at the start (2.8 cm from the end) is not having finished
    assert finish_time(t[:50], np.repeat(path[:1], 50, axis=0), path, goal_tolerance=0.03) is None


def test_best_window_rate_counts_frames_in_the_best_whole_window():
    steady = np.arange(0, 5.0, 1 / 15)                       # 15 Hz for 5 s
    assert best_window_rate(steady, 2.0) == pytest.approx(15.0)
    assert best_window_rate(steady[steady < 1.9], 2.0) is None      # no whole window yet
    # a 1.5 s stall after the first frames (start-up contention): the best window is after it
    stalled = np.r_[steady[steady < 0.5], steady[steady > 2.0]]
    assert best_window_rate(stalled, 2.0) == pytest.approx(15.0)
    first_window = np.sum(stalled <= stalled[0] + 2.0) - 1
    assert first_window / 2.0 < 0.8 * 15                      # what a first-window check would have seen
    assert best_window_rate(np.arange(0, 6.0, 1 / 10), 2.0) == pytest.approx(10.0)   # a 10 Hz camera stays 10
    assert best_window_rate(np.random.default_rng(1).permutation(steady), 2.0) == pytest.approx(15.0)


def test_a_run_stopped_after_one_pose_still_has_a_report():
    """Real mode stopped 0.5 s after the start (one tracked pose while following, as when a restarted
    tracker never delivered): the report uses the last two poses, 3 cm and 4 cm beside the line, instead
    of failing with 'need >= 2 samples'."""
    from frog_twin.core.twin_recording import TwinRecording
    from frog_twin.core.twin_report import run_metrics
    rec = TwinRecording()
    rec.path = np.c_[np.linspace(0, 0.6, 50), np.zeros(50)]
    rec.truth = np.array([[0.0, 0.10, 0.03, 0.0], [1.0, 0.11, 0.04, 0.0]])
    rec.tracked = rec.truth.copy()
    rec.status = np.zeros((1, 10))
    rec.status[0, 0], rec.status[0, 8] = 0.5, 1      # FOLLOWING from t = 0.5 s
    m = run_metrics(rec, "line")
    assert m["mean_distance_m"] == pytest.approx(0.035, abs=1e-9)
    assert m["max_distance_m"] == pytest.approx(0.04, abs=1e-9)
    assert m["start_time_s"] == 0.5


def test_a_run_is_scored_up_to_its_end_not_what_was_recorded_while_the_nodes_stopped():
    """A line run to a 6 s time limit, decisions every 1.42 s from t = 1 s: the recorder kept the
    world (2 cm beside the line until 6 s, then 10 cm: the frog drifts on) and the planner's decisions
    (two more) while the nodes stopped. Scored to its end, the run has the 4 decisions before 6 s
    and the 2 cm offset; unbounded, the same recording has 6 and a larger mean."""
    from frog_twin.core.twin_recording import TwinRecording
    from frog_twin.core.twin_report import run_metrics
    rec = TwinRecording()
    rec.path = np.c_[np.linspace(0, 0.6, 50), np.zeros(50)]
    t = np.arange(0.0, 8.5, 0.1)
    rec.truth = np.c_[t, 0.01 * t, np.where(t <= 6.0 + 1e-9, 0.02, 0.10), np.zeros_like(t)]
    rec.tracked = rec.truth.copy()
    rec.status = np.zeros((1, 10))
    rec.status[0, 0], rec.status[0, 8] = 1.0, 1
    rec.primitives = [(1.0 + 1.42 * k, "F") for k in range(6)]      # 1.0 ... 8.1
    rec.fired = [(td + 0.05, [1, 1]) for td, _ in rec.primitives]
    ended = run_metrics(rec, "line", end_time=6.0)
    assert ended["decisions"] == 4 and ended["limb_firings"] == 4 and ended["end_time_s"] == 6.0
    assert ended["mean_distance_m"] == pytest.approx(0.02, abs=1e-9)
    whole = run_metrics(rec, "line")
    assert whole["decisions"] == 6 and whole["limb_firings"] == 6 and whole["end_time_s"] is None
    assert whole["mean_distance_m"] > 0.04
