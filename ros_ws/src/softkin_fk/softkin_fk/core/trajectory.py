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

The built-in curves 'L' (N = 55) and 'flame' (N = 85), waypoint CSV files and the workspace
they were placed in live in :mod:`softkin_fk.core.curves` (re-exported here).
"""
from __future__ import annotations

import dataclasses
import itertools
from typing import Callable, List, Optional

import numpy as np

from .curves import CURVES, FINGER_PLANE_Z, MM, curve_flame, curve_L, read_waypoints_csv  # noqa: F401
from .forward import FKResult, ForwardSolver
from .inverse import IKResult, solve_ik


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
                               fk_tol: float = 1e-4, progress: Optional[Callable] = None,
                               predictor: bool = True) -> ConfigurationSpace:
    """Forward kinematics on an actuation grid (n_per_axis ** n_a samples), warm started.

    Parameters
    ----------
    solver : ForwardSolver
    n_per_axis : int
        Samples per actuator between its lower bound and its upper bound.
    marker : str
        Tracked marker.
    fk_tol : float
        FK tolerance (m); the samples only seed IK (which re-solves at its own tolerance).
        The Newton solver stops after applying an exact Newton step shorter than this, so the
        error left is of second order: at 0.1 mm the 125 finger samples deviate at most
        1.6e-7 m from solves at 1e-10 m (the L-BFGS / local-global solvers are looser).
    predictor : bool
        Warm start each sample from its neighbour moved along the implicit sensitivity
        dx/dC (when the Newton solver applies: all R_w = 1), else from the neighbour itself.
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
    predict = predictor and solver.newton_applicable()
    for c in grid:
        x0 = active0 = None
        if prev is not None:
            x0 = prev.positions
            # a cable pulled further than in the neighbour starts taut
            active0 = prev.active | (c < prev.actuation - 1e-12)
            if predict:
                # first-order predictor along the implicit sensitivity (reusing the Newton
                # factorisation of the neighbour): Newton then starts within second order
                x0 = x0 + solver.sensitivity(prev, reuse_tol=np.inf, one_sided=False) @ (c - prev.actuation)
        r = solver.solve(c, x0=x0, tol=fk_tol, active0=active0)
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
                      marker: str = 'tip', progress: Optional[Callable] = None,
                      on_waypoint: Optional[Callable[[int, IKResult], Optional[bool]]] = None,
                      **ik_kw) -> TrajectoryResult:
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
    on_waypoint : callable, optional
        Called as ``on_waypoint(index, ik_result)`` after each waypoint; returning False stops
        the trajectory there (a cancel): the result then holds the waypoints done so far.
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
    lam = ik_kw.get('lam', 0.2e-3)
    iks = []
    for p in P:
        r = solve_ik(solver, p, markers=(marker,), initial=c, initial_fk=fk, **ik_kw)
        if fk is not None and r.error > lam:
            # A warm start is only a seed: a sample's shape has a loose tolerance, and a cable at
            # its rest length (s = 1, the bound) can sit slack or taut, where the search stalls.
            # Retry from a fresh FK solve of the same actuation, then with slack cables pulled
            # just off the bound, and keep the best result.
            hi = np.array([a.bounds[1] for a in solver.mesh.actuators], float)
            for start in (c, np.minimum(c, hi - 1e-3)):     # as is; slack cables pulled just taut
                retry = solve_ik(solver, p, markers=(marker,), initial=start, **ik_kw)
                r = retry if retry.error < r.error else r
                if r.error <= lam:
                    break
        iks.append(r)
        c, fk = r.actuation, r.fk
        if progress is not None:
            progress(1)
        if on_waypoint is not None and on_waypoint(len(iks) - 1, r) is False:
            break
    P = P[:len(iks)]
    reached = np.array([r.reached[0] for r in iks])
    errors = np.linalg.norm(reached - P, axis=1)
    return TrajectoryResult(targets=P, reached=reached, actuations=np.array([r.actuation for r in iks]),
                            errors=errors, reached_flags=errors <= lam,
                            iterations=np.array([r.iterations for r in iks]),
                            fk_solves=np.array([r.fk_solves for r in iks]), ik=iks)
