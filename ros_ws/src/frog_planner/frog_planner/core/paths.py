"""Reference paths for the frog planner (paper seed 000, "Control Algorithm and Software", eq. 15-17).

A :class:`Path` is a polyline of ``n_points`` points (100, as in the paper) spaced evenly by
arc length, in the world frame (metres, REP-103: x forward, y left). It answers the three
questions the cost function (eq. 19) asks about a pose: how far from the path, the path's
tangent heading there, and how far along the path (progress in [0, 1]). Progress is searched
in a window ahead of the previous progress, so it never jumps backwards, even on paths that
come back near their start (the ellipse's start and end).

The paper gives the curve families but not the numbers; the defaults below are the values in
the authors' logged reference paths (softmachineslab/frog, ``control_data/data/*p1.csv``):

- line: length 0.466 m;
- sinusoid: length 0.357 m, amplitude length / A = 0.042 m (A = 8.5), f = 10 rad over s in [0, 1];
- ellipse: length (major axis) 0.276 m, A = 1 (a circle of radius 0.138 m), s_f = 1 / 0.95,
  i.e. 95 % of a revolution so that the goal is not the start.
"""

import csv
import math
from dataclasses import dataclass

import numpy as np
from frog_common.se2 import wrap_angle

PAPER_N_POINTS = 100  # "100 evenly spaced points in [0, 1]"
LINE_LENGTH_M = 0.466
SINUSOID_LENGTH_M = 0.357
SINUSOID_A = 8.5
SINUSOID_F = 10.0
ELLIPSE_LENGTH_M = 0.276
ELLIPSE_A = 1.0
ELLIPSE_S_F = 1.0 / 0.95

_DENSE_SAMPLES = 4001  # samples of a parametric curve before arc-length resampling
_PROJECT_CHUNK = 4096  # positions per block when projecting (bounds memory at depth 4-5)


def resample_by_arc_length(points, n_points=PAPER_N_POINTS):
    """Resample a polyline to ``n_points`` points evenly spaced by arc length.

    Parameters
    ----------
    points : array_like, shape (M, 2)
        Polyline vertices in m, M >= 2, total length > 0. Repeated consecutive points are dropped.
    n_points : int
        Number of output points, >= 2.

    Returns
    -------
    numpy.ndarray, shape (n_points, 2)
        Points in m; the first and last equal the input's first and last.

    Raises
    ------
    ValueError
        If the input is not (M, 2), has non-finite values, fewer than 2 distinct points,
        or n_points < 2.
    """
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise ValueError(f"path points have shape {pts.shape}; expected (M, 2) x, y in m")
    if not np.all(np.isfinite(pts)):
        bad = int(np.flatnonzero(~np.all(np.isfinite(pts), axis=1))[0])
        raise ValueError(f"path point {bad} is {pts[bad].tolist()}; expected finite x, y in m")
    if int(n_points) < 2:
        raise ValueError(f"n_points {n_points} is too small; expected >= 2")
    step = np.hypot(*np.diff(pts, axis=0).T)
    keep = np.concatenate([[True], step > 0.0])
    pts = pts[keep]
    if len(pts) < 2:
        raise ValueError("path has fewer than 2 distinct points; expected a curve of non-zero length")
    arc = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))])
    target = np.linspace(0.0, arc[-1], int(n_points))
    out = np.column_stack([np.interp(target, arc, pts[:, 0]), np.interp(target, arc, pts[:, 1])])
    out[0], out[-1] = pts[0], pts[-1]
    return out


@dataclass(frozen=True)
class PathProjection:
    """Where poses lie relative to a path (the terms of eq. 19 before weighting).

    Attributes
    ----------
    progress : numpy.ndarray, shape (M,)
        Arc-length fraction s_c in [0, 1] of the closest point within the search window.
    distance : numpy.ndarray, shape (M,)
        Distance in m from the position to that closest point.
    tangent_heading : numpy.ndarray, shape (M,)
        Heading of the path tangent at that point, rad (``tangent_headings`` interpolated by arc length).
    closest_point : numpy.ndarray, shape (M, 2)
        The closest point, m.
    """

    progress: np.ndarray
    distance: np.ndarray
    tangent_heading: np.ndarray
    closest_point: np.ndarray


class Path:
    """A reference path: ``n_points`` points evenly spaced by arc length (paper: 100).

    Parameters
    ----------
    points : array_like, shape (M, 2)
        Any polyline in m (world frame), resampled by arc length.
    n_points : int
        Number of resampled points (default 100, as in the paper).
    progress_window : float
        Length in m of the window ahead of the previous progress in which the closest point
        is searched (default 0.3 m: more than three periods of swimming at 3 cm/s at depth 3).
    goal_tolerance : float
        Distance in m from the last point within which the goal counts as reached.
    goal_min_progress : float
        Progress in [0, 1] that must also be reached for the goal test when a progress is
        given (keeps the start of a near-closed path from counting as its end).
    goal_lateral_tolerance : float, optional
        Crossing the finish line (the normal through the last point) counts as reaching the
        goal only within this distance in m of the last point along that line; default
        (None): ``goal_tolerance``.
    name : str
        A label for logs and plots.

    Attributes
    ----------
    points : numpy.ndarray, shape (n_points, 2)
    tangent_headings : numpy.ndarray, shape (n_points,)
        Heading of the path's tangent at each point, rad (second-order differences of the points).
    curvatures : numpy.ndarray, shape (n_points,)
        Signed curvature at each point, 1/m (positive turning left).
    arc_length : numpy.ndarray, shape (n_points,)
        Cumulative arc length in m, from 0 to ``length``.
    length : float
        Total length in m.

    Examples
    --------
    >>> path = line_path(length=0.4)
    >>> path.progress_of([0.2, 0.01], previous_progress=0.0)
    0.5
    """

    def __init__(self, points, n_points=PAPER_N_POINTS, progress_window=0.3, goal_tolerance=0.03,
                 goal_min_progress=0.9, name="path", goal_lateral_tolerance=None):
        self.points = resample_by_arc_length(points, n_points)
        self.name = str(name)
        if not progress_window > 0.0:
            raise ValueError(f"progress_window {progress_window} m must be > 0")
        if not goal_tolerance > 0.0:
            raise ValueError(f"goal_tolerance {goal_tolerance} m must be > 0")
        if not 0.0 <= goal_min_progress <= 1.0:
            raise ValueError(f"goal_min_progress {goal_min_progress} must be in [0, 1]")
        self.progress_window = float(progress_window)
        self.goal_tolerance = float(goal_tolerance)
        self.goal_min_progress = float(goal_min_progress)
        if goal_lateral_tolerance is None:
            goal_lateral_tolerance = goal_tolerance
        if not goal_lateral_tolerance > 0.0:
            raise ValueError(f"goal_lateral_tolerance {goal_lateral_tolerance} m must be > 0")
        self.goal_lateral_tolerance = float(goal_lateral_tolerance)
        seg = np.diff(self.points, axis=0)
        self._segment_length = np.hypot(seg[:, 0], seg[:, 1])
        self.arc_length = np.concatenate([[0.0], np.cumsum(self._segment_length)])
        self.length = float(self.arc_length[-1])
        grad = np.gradient(self.points, axis=0, edge_order=2 if len(self.points) > 2 else 1)
        self.tangent_headings = np.arctan2(grad[:, 1], grad[:, 0])
        self._unwrapped_tangent = np.unwrap(self.tangent_headings)
        self.curvatures = (np.gradient(self._unwrapped_tangent, self.arc_length) if len(self.points) > 2
                           else np.zeros(len(self.points)))

    @classmethod
    def from_points(cls, points, **kwargs):
        """Path through any polyline (e.g. a parametric curve sampled densely). See :class:`Path`."""
        return cls(points, **kwargs)

    def point_at(self, progress):
        """Point at arc-length fraction(s) ``progress`` in [0, 1]; returns shape (..., 2) in m."""
        s = np.clip(np.asarray(progress, dtype=float), 0.0, 1.0) * self.length
        return np.stack([np.interp(s, self.arc_length, self.points[:, 0]),
                         np.interp(s, self.arc_length, self.points[:, 1])], axis=-1)

    def window(self, previous_progress=0.0):
        """Sub-polyline from ``previous_progress`` to ``progress_window`` m further along.

        Returns
        -------
        vertices : numpy.ndarray, shape (W + 1, 2)
            Vertices in m (first is exactly the point at ``previous_progress``).
        vertex_arc : numpy.ndarray, shape (W + 1,)
            Their arc length in m.
        """
        s0 = float(np.clip(previous_progress, 0.0, 1.0)) * self.length
        s1 = min(s0 + self.progress_window, self.length)
        inner = (self.arc_length > s0) & (self.arc_length < s1)
        arc = np.concatenate([[s0], self.arc_length[inner], [s1]])
        verts = np.column_stack([np.interp(arc, self.arc_length, self.points[:, 0]),
                                 np.interp(arc, self.arc_length, self.points[:, 1])])
        return verts, arc

    def tangent_heading_at(self, progress):
        """Tangent heading in rad at progress in [0, 1]: ``tangent_headings`` interpolated along the arc."""
        s = np.clip(np.asarray(progress, dtype=float), 0.0, 1.0) * self.length
        return wrap_angle(np.interp(s, self.arc_length, self._unwrapped_tangent))

    def curvature_at(self, progress):
        """Signed curvature in 1/m (positive turning left) at progress in [0, 1].

        d(tangent heading)/d(arc length) at the points, interpolated along the arc.
        """
        s = np.clip(np.asarray(progress, dtype=float), 0.0, 1.0) * self.length
        return np.interp(s, self.arc_length, self.curvatures)

    def project(self, positions, previous_progress=0.0):
        """Closest points of ``positions`` on the path window ahead of ``previous_progress``.

        The search covers arc length [s_prev, s_prev + progress_window] only, so the result's
        progress is never below ``previous_progress`` (monotone progress) and a path that
        comes back near its start (ellipse) cannot be mistaken for its end.

        Parameters
        ----------
        positions : array_like, shape (M, 2) or (2,)
            Positions in m (world frame).
        previous_progress : float
            Progress in [0, 1] the search starts from.

        Returns
        -------
        PathProjection
            Arrays of shape (M,) (or scalars' shape (1,) for a single position).
        """
        pos = np.atleast_2d(np.asarray(positions, dtype=float))[:, :2]
        verts, arc = self.window(previous_progress)
        if len(pos) > _PROJECT_CHUNK:
            parts = [self._project_window(pos[i:i + _PROJECT_CHUNK], verts, arc)
                     for i in range(0, len(pos), _PROJECT_CHUNK)]
            return PathProjection(*(np.concatenate([getattr(p, f) for p in parts])
                                    for f in ("progress", "distance", "tangent_heading", "closest_point")))
        return self._project_window(pos, verts, arc)

    def _project_window(self, pos, verts, arc):
        a = verts[:-1]                      # (W, 2)
        d = verts[1:] - a                   # (W, 2)
        seg_len2 = np.einsum("ij,ij->i", d, d)
        rel = pos[:, None, :] - a[None, :, :]             # (M, W, 2)
        t = np.einsum("mwj,wj->mw", rel, d) / np.where(seg_len2 > 0.0, seg_len2, 1.0)
        t = np.clip(t, 0.0, 1.0)
        closest = a[None] + t[..., None] * d[None]        # (M, W, 2)
        dist2 = np.sum((pos[:, None, :] - closest) ** 2, axis=-1)
        best = np.argmin(dist2, axis=1)
        rows = np.arange(len(pos))
        s = arc[best] + t[rows, best] * (arc[best + 1] - arc[best])
        # The tangent is interpolated along the arc, so it is continuous across vertices.
        return PathProjection(progress=s / self.length, distance=np.sqrt(dist2[rows, best]),
                              tangent_heading=wrap_angle(np.interp(s, self.arc_length, self._unwrapped_tangent)),
                              closest_point=closest[rows, best])

    def progress_of(self, point, previous_progress=0.0):
        """Progress in [0, 1] of one position, searched ahead of ``previous_progress`` (monotone).

        Parameters
        ----------
        point : array_like, shape (2,) or (3,)
            Position (x, y) in m; a pose (x, y, heading) is accepted.
        previous_progress : float or None
            Progress the search starts from; None means 0 (the start of the path).

        Returns
        -------
        float
            Progress >= previous_progress.
        """
        prev = 0.0 if previous_progress is None else previous_progress
        return float(self.project(np.asarray(point, dtype=float)[:2], prev).progress[0])

    def distance_to(self, point):
        """Distance in m from a position to the nearest point of the whole path (no window)."""
        p = np.asarray(point, dtype=float)[:2]
        a = self.points[:-1]
        d = np.diff(self.points, axis=0)
        t = np.clip(np.einsum("ij,ij->i", p - a, d) / np.maximum(np.einsum("ij,ij->i", d, d), 1e-300), 0.0, 1.0)
        return float(np.min(np.hypot(*(a + t[:, None] * d - p).T)))

    def goal_reached(self, pose, progress=None, previous_pose=None):
        """Whether a pose has reached the end of the path.

        Parameters
        ----------
        pose : array_like, shape (2,) or (3,)
            Position (x, y) in m, heading ignored.
        progress : float, optional
            The planner's current (monotone) progress. When given, it must also be at least
            ``goal_min_progress``; pass it for paths whose start lies near their end. A
            progress of 1 also counts when the robot has crossed the line through the last
            point normal to the path (the finish line) within ``goal_lateral_tolerance`` of
            the last point along that line (a robot far to the side has not reached the goal).
        previous_pose : array_like, shape (2,) or (3,), optional
            The position at the previous check. When given, the crossing is where the segment
            from it to ``pose`` meets the finish line (so passing the end far to the side and
            drifting into the band afterwards does not count); without it, ``pose`` must be
            past the line and within the band.

        Returns
        -------
        bool
            True when within ``goal_tolerance`` of the last point (and far enough along), or
            crossing the finish line with progress 1 within the lateral tolerance.
        """
        p = np.asarray(pose, dtype=float)[:2]
        offset = p - self.points[-1]
        near = float(np.hypot(*offset)) <= self.goal_tolerance
        if progress is None:
            return bool(near)
        c, s = np.cos(self.tangent_headings[-1]), np.sin(self.tangent_headings[-1])
        along = offset[0] * c + offset[1] * s
        lateral = -offset[0] * s + offset[1] * c
        if previous_pose is not None:
            q = np.asarray(previous_pose, dtype=float)[:2] - self.points[-1]
            along0, lateral0 = q[0] * c + q[1] * s, -q[0] * s + q[1] * c
            if along0 < 0.0 <= along:                    # crossed during this step: where?
                lateral = lateral0 + (lateral - lateral0) * (-along0) / (along - along0)
            elif along0 >= 0.0:                          # was already past the line
                along = -1.0
        crossed = progress >= 1.0 and along >= 0.0 and abs(lateral) <= self.goal_lateral_tolerance
        return bool((near and progress >= self.goal_min_progress) or crossed)


def _place(local_points, start, heading):
    """Rotate local curve points by ``heading`` and shift them to ``start`` (world frame)."""
    c, s = math.cos(heading), math.sin(heading)
    rot = np.array([[c, -s], [s, c]])
    return np.asarray(start, dtype=float)[None, :] + local_points @ rot.T


def parametric_path(curve, s_values=None, start=(0.0, 0.0), heading=0.0, **kwargs):
    """Path from a parametric curve p(s), sampled densely then resampled by arc length.

    Parameters
    ----------
    curve : callable
        Maps s, shape (K,), to points, shape (K, 2), in m (local frame: starts where the robot
        starts, x along its initial heading).
    s_values : array_like, shape (K,), optional
        Parameter samples (default 4001 values evenly in [0, 1]).
    start : array_like, shape (2,)
        World position in m of the local origin.
    heading : float
        World heading in rad of the local x axis.
    **kwargs
        Passed to :class:`Path` (n_points, progress_window, goal_tolerance, name, ...).

    Returns
    -------
    Path
    """
    s = np.linspace(0.0, 1.0, _DENSE_SAMPLES) if s_values is None else np.asarray(s_values, dtype=float)
    local = np.asarray(curve(s), dtype=float)
    if local.shape != (len(s), 2):
        raise ValueError(f"curve returned shape {local.shape}; expected ({len(s)}, 2)")
    return Path(_place(local, start, heading), **kwargs)


def line_path(length=LINE_LENGTH_M, start=(0.0, 0.0), heading=0.0, **kwargs):
    """Straight line, eq. 15: p(s) = [l s, 0], s in [0, 1]. ``length`` is l in m."""
    if not length > 0.0:
        raise ValueError(f"line length {length} m must be > 0")
    kwargs.setdefault("name", "line")
    return parametric_path(lambda s: np.column_stack([length * s, np.zeros_like(s)]),
                           np.array([0.0, 1.0]), start, heading, **kwargs)


def sinusoid_path(length=SINUSOID_LENGTH_M, A=SINUSOID_A, f=SINUSOID_F, start=(0.0, 0.0), heading=0.0, **kwargs):
    """Sinusoid, eq. 16: p(s) = [l s, (l / A) sin(f s)], s in [0, 1].

    Parameters
    ----------
    length : float
        l in m (extent along the initial heading).
    A : float
        Ratio of length to amplitude (amplitude = l / A, m).
    f : float
        Angular frequency in rad per unit s (f / 2 pi waves over the path).
    """
    if not length > 0.0 or not A > 0.0 or not f > 0.0:
        raise ValueError(f"sinusoid length {length} m, A {A}, f {f} must all be > 0")
    kwargs.setdefault("name", "sinusoid")
    return parametric_path(lambda s: np.column_stack([length * s, length / A * np.sin(f * s)]),
                           None, start, heading, **kwargs)


def ellipse_path(length=ELLIPSE_LENGTH_M, A=ELLIPSE_A, s_f=ELLIPSE_S_F, start=(0.0, 0.0), heading=0.0, **kwargs):
    """Ellipse, eq. 17: p(s) = [l/2 (1 - cos(2 pi s / s_f)), l/(2A) sin(2 pi s / s_f)], s in [0, 1].

    Parameters
    ----------
    length : float
        l in m: the axis along the initial heading (the robot starts at one of its ends,
        moving sideways to it, counter-clockwise).
    A : float
        Ratio of that axis to the other one.
    s_f : float
        Final value of s for a full turn; s_f > 1 stops short of closing (default 1 / 0.95).
    """
    if not length > 0.0 or not A > 0.0 or not s_f > 0.0:
        raise ValueError(f"ellipse length {length} m, A {A}, s_f {s_f} must all be > 0")
    kwargs.setdefault("name", "ellipse")

    def curve(s):
        phase = 2.0 * np.pi * s / s_f
        return np.column_stack([length / 2.0 * (1.0 - np.cos(phase)), length / (2.0 * A) * np.sin(phase)])

    return parametric_path(curve, None, start, heading, **kwargs)


def waypoint_path_from_csv(file_path, **kwargs):
    """Path through waypoints read from a CSV file with a header row naming columns ``x`` and ``y`` (m).

    Other columns are ignored. Blank lines are skipped.

    Raises
    ------
    FileNotFoundError
        If the file does not exist.
    ValueError
        If the header lacks x or y, a value is not a finite number (the line is named),
        or there are fewer than 2 distinct waypoints.
    """
    with open(file_path, newline="") as fh:
        reader = csv.reader(fh)
        header = next(reader, None)
        if header is None:
            raise ValueError(f"{file_path}: empty file; expected a header row with columns x,y (m)")
        names = [h.strip().lower() for h in header]
        if "x" not in names or "y" not in names:
            raise ValueError(f"{file_path}: header {header} lacks columns 'x' and 'y'; expected a header row "
                             "such as 'x,y' (values in m)")
        ix, iy = names.index("x"), names.index("y")
        rows = []
        for line_no, row in enumerate(reader, start=2):
            if not row or all(not c.strip() for c in row):
                continue
            try:
                x, y = float(row[ix]), float(row[iy])
            except (IndexError, ValueError):
                raise ValueError(f"{file_path}: line {line_no} {row} has no numeric x, y; expected metres") from None
            if not (math.isfinite(x) and math.isfinite(y)):
                raise ValueError(f"{file_path}: line {line_no} has x={x}, y={y}; expected finite metres")
            rows.append((x, y))
    if len(rows) < 2:
        raise ValueError(f"{file_path}: {len(rows)} waypoint(s); expected at least 2")
    kwargs.setdefault("name", "waypoints")
    try:
        return Path(np.array(rows), **kwargs)
    except ValueError as exc:
        raise ValueError(f"{file_path}: {exc}") from None


PATH_KINDS = ("line", "sinusoid", "ellipse", "waypoints")


def path_from_spec(kind, start=(0.0, 0.0), heading=0.0, waypoint_file=None, start_tangent=None, **params):
    """Build a path by name, for nodes and evaluators that take the path type as a setting.

    Parameters
    ----------
    kind : {"line", "sinusoid", "ellipse", "waypoints"}
        "sine" is accepted for "sinusoid".
    start : array_like, shape (2,)
        World position in m where the curve starts (ignored for waypoints, which are in the world frame).
    heading : float
        World heading in rad of the curve's local x axis (ignored for waypoints).
    waypoint_file : str or os.PathLike, optional
        CSV file for kind "waypoints".
    start_tangent : float, optional
        If given (rad), ``heading`` is ignored and the curve is rotated so that its tangent at
        the start points this way (e.g. the robot's heading, so the ellipse, whose tangent at
        the start is along its local +y, begins straight ahead of the robot).
    **params
        Curve parameters (``length``, ``A``, ``f``, ``s_f``) and :class:`Path` settings
        (``n_points``, ``progress_window``, ``goal_tolerance``, ``goal_min_progress``,
        ``goal_lateral_tolerance``).

    Returns
    -------
    Path

    Raises
    ------
    ValueError
        For an unknown kind, a parameter the kind does not take, or a missing waypoint file name.

    Examples
    --------
    >>> path_from_spec("ellipse", start=(0.1, 0.2), heading=0.5, length=0.3).name
    'ellipse'
    """
    name = {"sine": "sinusoid"}.get(str(kind).lower(), str(kind).lower())
    curve_params = {"line": {"length"}, "sinusoid": {"length", "A", "f"}, "ellipse": {"length", "A", "s_f"},
                    "waypoints": set()}
    if name not in curve_params:
        raise ValueError(f"path type {kind!r} is unknown; expected one of {list(PATH_KINDS)}")
    allowed = curve_params[name] | {"n_points", "progress_window", "goal_tolerance", "goal_min_progress", "name",
                                     "goal_lateral_tolerance"}
    extra = sorted(set(params) - allowed)
    if extra:
        raise ValueError(f"path type {name!r} takes no parameter(s) {extra}; expected some of {sorted(allowed)}")
    if name == "waypoints":
        if not waypoint_file:
            raise ValueError("path type 'waypoints' needs a waypoint_file (CSV with columns x,y in m)")
        return waypoint_path_from_csv(waypoint_file, **params)
    factory = {"line": line_path, "sinusoid": sinusoid_path, "ellipse": ellipse_path}[name]
    if start_tangent is not None:
        local_tangent = float(factory(**params).tangent_headings[0])
        heading = float(start_tangent) - local_tangent
    return factory(start=start, heading=heading, **params)
