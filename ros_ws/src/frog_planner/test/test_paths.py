"""Paths follow eq. 15-17, are resampled evenly by arc length, and report monotone progress."""

import math

import numpy as np
import pytest

from frog_planner.core.paths import (Path, ellipse_path, line_path, parametric_path, sinusoid_path,
                                     waypoint_path_from_csv)


def _chords(points):
    return np.hypot(*np.diff(points, axis=0).T)


def test_line_is_eq15():
    path = line_path(length=0.5)
    assert path.points.shape == (100, 2)
    np.testing.assert_allclose(path.points[:, 0], np.linspace(0.0, 0.5, 100), atol=1e-12)
    np.testing.assert_allclose(path.points[:, 1], 0.0, atol=1e-12)
    np.testing.assert_allclose(path.tangent_headings, 0.0, atol=1e-12)
    assert path.length == pytest.approx(0.5)


def test_sinusoid_points_lie_on_eq16_evenly_spaced():
    l, A, f = 0.36, 8.5, 10.0
    path = sinusoid_path(length=l, A=A, f=f)
    x, y = path.points.T
    np.testing.assert_allclose(y, l / A * np.sin(f * x / l), atol=2e-6)   # eq. 16 with s = x / l
    assert x[0] == 0.0 and x[-1] == pytest.approx(l)
    chords = _chords(path.points)
    assert np.ptp(chords) / chords.mean() < 2e-3
    # Tangent heading from the derivative of eq. 16: dp/ds = [l, (l / A) f cos(f s)].
    s = x / l
    expected = np.arctan2(l / A * f * np.cos(f * s), l)
    np.testing.assert_allclose(path.tangent_headings, expected, atol=0.01)


@pytest.mark.parametrize("A", [1.0, 2.0])
def test_ellipse_points_lie_on_eq17(A):
    l, s_f = 0.28, 1.0 / 0.95
    path = ellipse_path(length=l, A=A, s_f=s_f)
    x, y = path.points.T
    np.testing.assert_allclose(((x - l / 2) / (l / 2)) ** 2 + (y / (l / (2 * A))) ** 2, 1.0, atol=1e-4)
    np.testing.assert_allclose(path.points[0], [0.0, 0.0], atol=1e-15)
    end = 2 * math.pi / s_f
    np.testing.assert_allclose(path.points[-1], [l / 2 * (1 - math.cos(end)), l / (2 * A) * math.sin(end)],
                               atol=1e-12)
    chords = _chords(path.points)
    assert np.ptp(chords) / chords.mean() < 2e-3
    if A == 1.0:
        assert path.length == pytest.approx(math.pi * l / s_f, rel=5e-4)   # a circle's arc (chords: -1.5e-4)
    # Counter-clockwise start: tangent along +y at s = 0.
    assert path.tangent_headings[0] == pytest.approx(math.pi / 2, abs=0.05)


def test_start_and_heading_place_the_curve():
    path = line_path(length=0.3, start=(1.0, 2.0), heading=math.pi / 2)
    np.testing.assert_allclose(path.points[-1], [1.0, 2.3], atol=1e-12)
    np.testing.assert_allclose(path.tangent_headings, math.pi / 2, atol=1e-12)


def test_parametric_and_polyline_paths_are_resampled_to_100_points():
    path = parametric_path(lambda s: np.column_stack([s, s ** 2]), n_points=100)
    np.testing.assert_allclose(path.points[:, 1], path.points[:, 0] ** 2, atol=1e-6)
    corner = Path.from_points([[0, 0], [1, 0], [1, 1]])
    assert corner.points.shape == (100, 2)
    # Point i sits at arc length 2 i / 99 of the original polyline (the corner itself is cut).
    arc = 2.0 * np.arange(100) / 99
    expected = np.where(arc[:, None] <= 1.0, np.column_stack([arc, 0 * arc]),
                        np.column_stack([np.ones(100), arc - 1.0]))
    np.testing.assert_allclose(corner.points, expected, atol=1e-12)
    with pytest.raises(ValueError, match="fewer than 2 distinct points"):
        Path.from_points([[0.1, 0.2], [0.1, 0.2]])
    with pytest.raises(ValueError, match=r"shape \(3,\)"):
        Path.from_points([0.0, 1.0, 2.0])


def _brute_force_distance(path, point, s_lo, s_hi):
    """Distance from point to the path between arc lengths s_lo and s_hi, by dense sampling."""
    s = np.linspace(s_lo, s_hi, 200001)
    xs = np.interp(s, path.arc_length, path.points[:, 0])
    ys = np.interp(s, path.arc_length, path.points[:, 1])
    d = np.hypot(xs - point[0], ys - point[1])
    i = int(np.argmin(d))
    return d[i], s[i] / path.length


def test_projection_matches_brute_force_within_the_window():
    path = sinusoid_path()
    rng = np.random.default_rng(3)
    for prev in (0.0, 0.3, 0.7):
        s_lo = prev * path.length
        s_hi = min(s_lo + path.progress_window, path.length)
        for _ in range(10):
            q = path.point_at(rng.uniform(prev, 1.0)) + rng.normal(0.0, 0.02, 2)
            proj = path.project(q, prev)
            d, s = _brute_force_distance(path, q, s_lo, s_hi)
            assert proj.distance[0] == pytest.approx(d, abs=1e-5)
            assert proj.progress[0] >= prev
            assert proj.progress[0] == pytest.approx(s, abs=2e-3) or d > 0.02


def test_progress_is_monotone_around_the_ellipse_and_not_fooled_by_its_end():
    path = ellipse_path()
    # The ellipse ends 4 cm from its start: a global nearest-point search would call the start "done".
    end_gap = float(np.hypot(*(path.points[-1] - path.points[0])))
    assert 0.02 < end_gap < 0.06
    assert path.progress_of(path.points[-1], previous_progress=0.0) < 0.05
    # A robot circling the path with lateral noise, including a stretch where it drifts back.
    s_true = np.concatenate([np.linspace(0.0, 0.5, 40), np.linspace(0.5, 0.45, 5), np.linspace(0.45, 1.0, 60)])
    rng = np.random.default_rng(7)
    progress, history = 0.0, []
    for s in s_true:
        q = path.point_at(s) + rng.normal(0.0, 0.005, 2)
        progress = path.progress_of(q, progress)
        history.append(progress)
    assert np.all(np.diff(history) >= 0.0)
    assert history[0] < 0.05
    assert history[-1] > 0.98
    # Tracks the true progress wherever the robot moves forwards.
    forward = np.r_[np.arange(40), np.arange(45, 105)]
    assert np.max(np.abs(np.array(history)[forward] - s_true[forward])) < 0.08


def test_goal_reached():
    path = line_path(length=0.4)
    assert path.goal_reached([0.39, 0.01, 0.0])
    assert not path.goal_reached([0.3, 0.0, 0.0])
    closed = ellipse_path(s_f=1.0)            # start == end
    assert closed.goal_reached([0.0, 0.0])    # without progress the position alone decides
    assert not closed.goal_reached([0.0, 0.0], progress=0.0)
    assert closed.goal_reached([0.0, 0.0], progress=0.99)
    # Past the finish line (x >= 0.4) with progress 1 counts only within the lateral
    # tolerance (default: goal_tolerance, 3 cm) of the end: 2.5 cm to the side yes, 8 cm no.
    assert path.goal_reached([0.45, 0.025], progress=1.0)
    assert path.goal_reached([0.45, -0.025], progress=1.0)
    assert not path.goal_reached([0.41, 0.08], progress=1.0)
    assert not path.goal_reached([0.41, -0.08], progress=1.0)
    assert not path.goal_reached([0.45, 0.025], progress=0.98)
    assert not path.goal_reached([0.39, 0.08], progress=1.0)
    wide = line_path(length=0.4, goal_lateral_tolerance=0.1)
    assert wide.goal_reached([0.41, 0.08], progress=1.0)
    # The finish line of a path ending upwards (+y) is horizontal; lateral is along x.
    up = line_path(length=0.4, heading=np.pi / 2)
    assert up.goal_reached([0.02, 0.45], progress=1.0)
    assert not up.goal_reached([0.05, 0.45], progress=1.0)
    # With the previous position, the crossing point decides: passing the end 5 cm to the side
    # and then drifting into the band does not count; crossing 1 cm to the side does.
    assert not path.goal_reached([0.45, 0.02], progress=1.0, previous_pose=[0.42, 0.05])
    assert not path.goal_reached([0.45, 0.02], progress=1.0, previous_pose=[0.38, 0.09])   # y = 0.06 at x = 0.4
    assert path.goal_reached([0.42, 0.02], progress=1.0, previous_pose=[0.38, 0.0])        # y = 0.01 at x = 0.4
    assert path.goal_reached([0.39, 0.0], progress=1.0, previous_pose=[0.30, 0.0])        # near the end counts
    with pytest.raises(ValueError, match="goal_lateral_tolerance"):
        line_path(goal_lateral_tolerance=0.0)


def test_waypoints_from_csv(tmp_path):
    good = tmp_path / "wp.csv"
    good.write_text("x,y,note\n0,0,start\n0.2,0\n\n0.2,0.1,end\n")
    path = waypoint_path_from_csv(good)
    assert path.length == pytest.approx(0.3)
    np.testing.assert_allclose(path.points[[0, -1]], [[0, 0], [0.2, 0.1]])


@pytest.mark.parametrize("text, words", [
    ("", "empty file"),
    ("0,0\n1,1\n", r"lacks columns 'x' and 'y'"),
    ("x,y\n0,0\n0.1,abc\n", r"line 3 .* has no numeric x, y"),
    ("x,y\n0,0\n0.1\n", r"line 3 .* has no numeric x, y"),
    ("x,y\n0,0\nnan,1\n", "line 3 has x=nan"),
    ("x,y\n0,0\n", r"1 waypoint\(s\); expected at least 2"),
    ("x,y\n0,0\n0,0\n", "fewer than 2 distinct points"),
])
def test_bad_waypoint_files_are_rejected(tmp_path, text, words):
    bad = tmp_path / "bad.csv"
    bad.write_text(text)
    with pytest.raises(ValueError, match=words):
        waypoint_path_from_csv(bad)


def test_missing_waypoint_file(tmp_path):
    with pytest.raises(FileNotFoundError):
        waypoint_path_from_csv(tmp_path / "none.csv")


@pytest.mark.parametrize("factory, kwargs", [(line_path, {"length": 0.0}), (sinusoid_path, {"A": 0.0}),
                                             (ellipse_path, {"s_f": -1.0})])
def test_bad_curve_parameters_are_rejected(factory, kwargs):
    with pytest.raises(ValueError, match="must"):
        factory(**kwargs)


def test_path_from_spec_builds_each_kind(tmp_path):
    from frog_planner.core.paths import path_from_spec
    np.testing.assert_allclose(path_from_spec("line", length=0.2).points[-1], [0.2, 0.0], atol=1e-12)
    sine = path_from_spec("sine", start=(1.0, 0.0), heading=math.pi, length=0.3, A=10.0, f=5.0)
    np.testing.assert_allclose(sine.points[-1], [1.0 - 0.3, -0.03 * math.sin(5.0)], atol=1e-9)
    ellipse = path_from_spec("ellipse", length=0.2, A=2.0, s_f=1.0)
    assert np.max(np.abs(ellipse.points[:, 1])) == pytest.approx(0.05, rel=1e-3)
    csv_file = tmp_path / "wp.csv"
    csv_file.write_text("x,y\n0,0\n0,0.5\n")
    assert path_from_spec("waypoints", waypoint_file=csv_file).length == pytest.approx(0.5)
    with pytest.raises(ValueError, match="path type 'spiral' is unknown"):
        path_from_spec("spiral")
    with pytest.raises(ValueError, match=r"path type 'line' takes no parameter\(s\) \['A'\]"):
        path_from_spec("line", A=3.0)
    with pytest.raises(ValueError, match="needs a waypoint_file"):
        path_from_spec("waypoints")


def test_projection_in_blocks_equals_one_block():
    path = ellipse_path()
    rng = np.random.default_rng(0)
    pts = path.point_at(rng.uniform(0.0, 0.3, 9000)) + rng.normal(0.0, 0.01, (9000, 2))
    whole = path.project(pts, 0.05)
    first = path.project(pts[:100], 0.05)
    np.testing.assert_array_equal(whole.distance[:100], first.distance)
    np.testing.assert_array_equal(whole.progress[-5:], path.project(pts[-5:], 0.05).progress)


@pytest.mark.parametrize("kind", ["line", "sinusoid", "ellipse"])
def test_start_tangent_aligns_the_curve_with_the_robot(kind):
    from frog_planner.core.paths import path_from_spec
    path = path_from_spec(kind, start=(0.2, -0.1), start_tangent=0.7)
    np.testing.assert_allclose(path.points[0], [0.2, -0.1], atol=1e-12)
    # Direction of the first short chord, by hand, against the requested heading.
    chord = path.points[1] - path.points[0]
    assert math.atan2(chord[1], chord[0]) == pytest.approx(0.7, abs=0.05)
