"""Trajectory following (Algorithm 3) and the built-in target curves.

1. A sampled configuration space P_w: forward kinematics on a grid of actuations
   (``n_per_axis`` values per actuator between its lower bound and rest; 5^3 = 125 samples for
   the 3-tendon finger, Fig. 12b), visited in serpentine order so that every solve is warm
   started from its neighbour.
2. The first waypoint starts IK from the closest sample (actuation and deformed shape).
3. Every following waypoint starts IK from the previous solution (warm start).

A waypoint outside the workspace is not reached; IK then returns the nearest point it can
reach, and because each solve starts from the previous one the achieved path stays continuous
and inside the workspace (Fig. 14).

Built-in curves (the finger's bending plane z = 12.5 mm; metres at the API):

* ``'L'`` (N = 55): from (98, 58) mm down to the corner (98, 51) mm, then to (104, 51) mm,
  sampled uniformly by arc length (an "L", Fig. 13).
* ``'flame'`` (N = 85): a closed flame outline centred at (101, 53) mm, about 6 mm wide and
  9 mm tall, with a pointed top, sampled uniformly in its parameter.

The finger's three cables all run on its upper side, so its workspace is a curved band
(about 10-15 mm wide) from the rest tip (120, 25) mm up to about (75, 75) mm; both curves lie in
the band's middle section. Waypoints the finger cannot reach are reported with the nearest
reachable point (see ``softkin trajectory`` output).
"""
from __future__ import annotations

import dataclasses
import itertools
from typing import Callable, List, Optional

import numpy as np

from .forward import FKResult, ForwardSolver
from .inverse import IKResult, solve_ik

MM = 1e-3
FINGER_PLANE_Z = 12.5 * MM


def curve_L(n: int = 55) -> np.ndarray:
    """The 'L' trajectory: (n, 3) points (m), uniform in arc length."""
    corners = np.array([[98.0, 58.0], [98.0, 51.0], [104.0, 51.0]]) * MM
    seg = np.linalg.norm(np.diff(corners, axis=0), axis=1)
    s = np.linspace(0.0, seg.sum(), n)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    pts = np.empty((n, 2))
    for i, si in enumerate(s):
        k = min(np.searchsorted(cum, si, side='right') - 1, len(seg) - 1)
        u = (si - cum[k]) / seg[k]
        pts[i] = corners[k] + u * (corners[k + 1] - corners[k])
    return np.column_stack([pts, np.full(n, FINGER_PLANE_Z)])


def curve_flame(n: int = 85) -> np.ndarray:
    """The 'flame' trajectory: (n, 3) points (m) of a closed flame outline."""
    t = np.linspace(0.0, 2 * np.pi, n)
    # a teardrop: round bottom, pointed top (flame tip at t = pi / 2)
    w = 2.5 * np.cos(t) * (1 - 0.5 * (np.sin(t) > 0) * np.sin(t) ** 2)
    h = 4.0 * np.sin(t) - 0.7 * np.sin(3 * t)
    pts = np.column_stack([101.0 + 1.2 * w, 53.0 + h]) * MM
    return np.column_stack([pts, np.full(n, FINGER_PLANE_Z)])


CURVES = {'L': curve_L, 'flame': curve_flame}


def read_waypoints_csv(path: str, scale: float = 1.0) -> np.ndarray:
    """Waypoints from a CSV file with columns x, y[, z] (header optional).

    Parameters
    ----------
    path : str
    scale : float
        Factor to metres (0.001 for millimetres). Missing z is the finger plane.

    Returns
    -------
    ndarray, shape (n, 3)

    Raises
    ------
    ValueError
        If the file has fewer than 2 columns or no rows.
    """
    rows = []
    with open(path) as fh:
        for k, line in enumerate(fh):
            line = line.strip()
            if not line or line.startswith('#'):
                continue
            parts = [p for p in line.replace(';', ',').split(',') if p.strip() != '']
            try:
                vals = [float(p) for p in parts]
            except ValueError:
                if k == 0:
                    continue  # header
                raise ValueError(f"{path}: line {k + 1} is not numeric: {line!r}")
            if len(vals) < 2:
                raise ValueError(f"{path}: line {k + 1} has {len(vals)} columns, expected x, y[, z]")
            rows.append(vals[:3])
    if not rows:
        raise ValueError(f"{path}: no waypoints found")
    out = np.array([r + [FINGER_PLANE_Z / scale] if len(r) == 2 else r for r in rows], float) * scale
    return out


@dataclasses.dataclass
class ConfigurationSpace:
    """Sampled configuration space P_w (Fig. 12b).

    Attributes
    ----------
    actuations : ndarray, shape (n_s, n_a)
    points : ndarray, shape (n_s, 3)
        Marker positions (m).
    results : list of FKResult
        Deformed shapes (for warm starts).
    """

    actuations: np.ndarray
    points: np.ndarray
    results: List[FKResult]

    def nearest(self, p: np.ndarray) -> int:
        """Index of the sample closest to point ``p`` (m)."""
        return int(np.argmin(np.linalg.norm(self.points - np.asarray(p), axis=1)))


def sample_configuration_space(solver: ForwardSolver, n_per_axis: int = 5, marker: str = 'tip',
                               fk_tol: float = 1e-6, progress: Optional[Callable] = None) -> ConfigurationSpace:
    """Forward kinematics on an actuation grid (n_per_axis ** n_a samples), warm started.

    Parameters
    ----------
    solver : ForwardSolver
    n_per_axis : int
        Samples per actuator between its lower bound and its upper bound.
    marker : str
        Tracked marker.
    fk_tol : float
        FK tolerance (m); the samples only seed IK (which re-solves at its own tolerance),
        so 1 um is ample.
    progress : callable, optional
        Called with the number of finished samples (e.g. a tqdm ``update``).

    Returns
    -------
    ConfigurationSpace
    """
    mesh = solver.mesh
    if n_per_axis < 2:
        raise ValueError(f"n_per_axis = {n_per_axis} must be >= 2")
    axes = [np.linspace(a.bounds[1], a.bounds[0], n_per_axis) for a in mesh.actuators]
    # serpentine (boustrophedon) order: consecutive samples differ in one actuator by one step
    grid = []
    for idx in itertools.product(range(n_per_axis), repeat=len(axes)):
        idx = list(idx)
        for d in range(1, len(idx)):
            if sum(idx[:d]) % 2 == 1:
                idx[d] = n_per_axis - 1 - idx[d]
        grid.append([axes[d][i] for d, i in enumerate(idx)])
    grid = np.array(grid)
    results, points = [], []
    prev = None
    for c in grid:
        r = solver.solve(c, x0=None if prev is None else prev.positions, tol=fk_tol,
                         active0=None if prev is None else prev.active)
        results.append(r)
        points.append(r.marker(mesh, marker))
        prev = r
        if progress is not None:
            progress(1)
    return ConfigurationSpace(grid, np.array(points), results)


@dataclasses.dataclass
class TrajectoryResult:
    """Result of :func:`follow_trajectory`.

    Attributes
    ----------
    targets, reached : ndarray, shape (N, 3)
        Waypoints and achieved marker positions (m).
    actuations : ndarray, shape (N, n_a)
    errors : ndarray, shape (N,)
        Distance of each achieved point from its waypoint (m).
    reached_flags : ndarray of bool, shape (N,)
        Waypoints reached within lambda.
    iterations, fk_solves : ndarray of int, shape (N,)
    """

    targets: np.ndarray
    reached: np.ndarray
    actuations: np.ndarray
    errors: np.ndarray
    reached_flags: np.ndarray
    iterations: np.ndarray
    fk_solves: np.ndarray
    ik: List[IKResult]


def follow_trajectory(solver: ForwardSolver, waypoints, config_space: Optional[ConfigurationSpace] = None,
                      marker: str = 'tip', progress: Optional[Callable] = None, **ik_kw) -> TrajectoryResult:
    """Algorithm 3: IK for each waypoint, the first from the nearest sample, then warm starts.

    Parameters
    ----------
    solver : ForwardSolver
    waypoints : array_like, shape (N, 3)
        Target marker positions (m).
    config_space : ConfigurationSpace, optional
        Sampled configuration space; without it the first IK starts from rest.
    marker : str
    progress : callable, optional
        Called with 1 after each waypoint.
    **ik_kw
        Passed to :func:`~softkin_fk.core.inverse.solve_ik` (``lam``, ``i_max``,
        ``direction``, ...).

    Returns
    -------
    TrajectoryResult
    """
    P = np.asarray(waypoints, float)
    if P.ndim != 2 or P.shape[1] != 3 or len(P) == 0:
        raise ValueError(f"waypoints have shape {P.shape}, expected (N, 3) metres")
    if config_space is not None:
        k = config_space.nearest(P[0])
        c, fk = config_space.actuations[k], config_space.results[k]
    else:
        c, fk = None, None
    iks = []
    for p in P:
        r = solve_ik(solver, p, markers=(marker,), initial=c, initial_fk=fk, **ik_kw)
        iks.append(r)
        c, fk = r.actuation, r.fk
        if progress is not None:
            progress(1)
    reached = np.array([r.reached[0] for r in iks])
    lam = ik_kw.get('lam', 0.2e-3)
    errors = np.linalg.norm(reached - P, axis=1)
    return TrajectoryResult(targets=P, reached=reached, actuations=np.array([r.actuation for r in iks]),
                            errors=errors, reached_flags=errors <= lam,
                            iterations=np.array([r.iterations for r in iks]),
                            fk_solves=np.array([r.fk_solves for r in iks]), ik=iks)
