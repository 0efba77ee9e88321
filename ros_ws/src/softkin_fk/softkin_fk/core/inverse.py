"""Inverse kinematics by numerical gradients and a soft line search (Algorithm 2, eq. 12-15).

The objective (eq. 12) is the squared distance of the tracked marker vertices from their
targets, J(C) = sum_p ||v_p^d(C) - v_p^c||^2 (m^2), with v^d from forward kinematics
(:class:`~softkin_fk.core.forward.ForwardSolver`, warm started from the current shape).

Per iteration (Algorithm 2):

1. central differences of the marker positions give the Jacobian dv/dC, hence grad J (eq. 14);
   at an actuation bound the difference is one-sided (``jacobian='central'``, the paper). With
   ``jacobian='implicit'`` the Jacobian is the exact derivative of the converged shape by the
   implicit function theorem (one back-substitution with the Newton factorisation instead of
   2 FK solves per actuator);
2. search direction: ``-grad J`` (``direction='gradient'``, the paper) or the Gauss-Newton
   direction ``-(K^T K + mu I)^-1 K^T r`` from the same Jacobian K (``'gauss-newton'``; same
   cost per iteration, far fewer iterations near a target);
3. soft line search (eq. 15): shrink the step from ``h = 1`` by ``tau`` (0.1) until J drops,
   then expand in increments of the accepted step while J keeps dropping;
4. actuations are projected onto their bounds at every trial.

The loop stops when the marker error ``sqrt(J)`` is at most ``lam`` (0.2 mm: the paper's
lambda, read as a distance), after ``i_max`` (30) iterations, or when no step decreases J.
A target that is not reached is reported as out of reach together with the closest point the
robot reached (a local minimiser of eq. 12 within the bounds).
"""
from __future__ import annotations

import dataclasses
from typing import Optional, Sequence

import numpy as np

from .forward import FKResult, ForwardSolver


@dataclasses.dataclass
class IKResult:
    """Result of :func:`solve_ik`.

    Attributes
    ----------
    actuation : ndarray, shape (n_a,)
        Actuation ratios found (within bounds).
    reached : ndarray, shape (n_m, 3)
        Marker positions (m) at that actuation.
    target : ndarray, shape (n_m, 3)
        Requested positions (m).
    error : float
        sqrt(J) (m): root of eq. 12 at the solution.
    iterations : int
        IK iterations (gradient evaluations).
    fk_solves : int
        Forward-kinematics solves used.
    success : bool
        ``error <= lam``.
    out_of_reach : bool
        The target was not reached: ``reached`` is the nearest reachable point found.
    fk : FKResult
        Forward kinematics at the solution (deformed shape, for warm starts).
    history : ndarray, shape (iterations + 1,)
        sqrt(J) per iteration (m).
    """

    actuation: np.ndarray
    reached: np.ndarray
    target: np.ndarray
    error: float
    iterations: int
    fk_solves: int
    success: bool
    out_of_reach: bool
    fk: FKResult
    history: np.ndarray


class _Objective:
    """J(C) of eq. 12 with warm-started forward kinematics and a small cache."""

    def __init__(self, solver: ForwardSolver, markers: Sequence[int], target: np.ndarray, fk_tol: float,
                 start: Optional[FKResult]):
        self.solver = solver
        self.markers = np.asarray(markers)
        self.target = target
        self.fk_tol = fk_tol
        self.base = start
        self.n = 0

        self.dx = None  # dx/dC at the base (implicit Jacobian): first-order warm starts

    def fk(self, c: np.ndarray) -> FKResult:
        self.n += 1
        b = self.base
        x0 = None if b is None else b.positions
        if b is not None and self.dx is not None:
            # predictor: the base shape moved along its sensitivity, so Newton starts within
            # second-order distance of the solution
            x0 = x0 + self.dx @ (np.asarray(c, float) - b.actuation)
        return self.solver.solve(c, x0=x0, tol=self.fk_tol, active0=None if b is None else b.active)

    def value(self, res: FKResult) -> float:
        d = res.positions[self.markers] - self.target
        return float(np.sum(d * d))


def solve_ik(solver: ForwardSolver, target, markers: Sequence[str] = ('tip',), initial=None,
             initial_fk: Optional[FKResult] = None, lam: float = 0.2e-3, i_max: int = 30, tau: float = 0.1,
             delta: float = 2e-3, direction: str = 'gradient', fk_tol: float = 1e-7,
             max_shrink: int = 8, max_expand: int = 30, jacobian: str = 'central') -> IKResult:
    """Actuation that brings marker vertices to target positions (Algorithm 2).

    Parameters
    ----------
    solver : ForwardSolver
        Forward kinematics of the robot.
    target : array_like, shape (3,) or (n_m, 3)
        Target position(s) (m) of the markers.
    markers : sequence of str
        Names of the tracked marker vertices (``mesh.markers``).
    initial : array_like, shape (n_a,), optional
        Initial actuation (default: rest, all 1.0).
    initial_fk : FKResult, optional
        Deformed shape at ``initial`` (warm start, Algorithm 3); computed if omitted.
    lam : float
        Stop when sqrt(J) <= lam (m); 0.2 mm as in the paper.
    i_max : int
        Iteration limit (30 in the paper).
    tau : float
        Shrinking ratio of the soft line search, in (0, 1).
    delta : float
        Central-difference step Delta C of eq. 14 (actuation ratio units).
    direction : {'gradient', 'gauss-newton'}
        Search direction (see module docstring).
    fk_tol : float
        Forward-kinematics tolerance (m). Must be well below the marker change caused by
        ``delta`` for meaningful differences.
    max_shrink, max_expand : int
        Limits of the line search.
    jacobian : {'central', 'implicit'}
        'central': central differences of eq. 14 (the paper; 2 FK solves per actuator).
        'implicit': the implicit-function-theorem sensitivity dx/dC = -H^{-1} d(grad E)/dC
        of the converged shape (:meth:`ForwardSolver.sensitivity`; no extra FK solve; needs
        all R_w = 1); it also gives the line search's FK solves a first-order warm start.

    Returns
    -------
    IKResult

    Raises
    ------
    ValueError
        On a target of the wrong shape, unknown markers or bad parameters.
    """
    mesh = solver.mesh
    for name in markers:
        if name not in mesh.markers:
            raise ValueError(f"unknown marker {name!r}; the mesh has {sorted(mesh.markers)}")
    tgt = np.atleast_2d(np.asarray(target, float))
    if tgt.shape != (len(markers), 3) or not np.all(np.isfinite(tgt)):
        raise ValueError(f"target has shape {np.shape(target)}, expected ({len(markers)}, 3) finite metres")
    if not 0 < tau < 1:
        raise ValueError(f"tau = {tau} must lie in (0, 1)")
    if direction not in ('gradient', 'gauss-newton'):
        raise ValueError(f"direction {direction!r} is not 'gradient' or 'gauss-newton'")
    if jacobian not in ('central', 'implicit'):
        raise ValueError(f"jacobian {jacobian!r} is not 'central' or 'implicit'")
    if lam <= 0 or i_max < 1 or delta <= 0:
        raise ValueError(f"need lam > 0, i_max >= 1, delta > 0; got {lam}, {i_max}, {delta}")
    lo = np.array([a.bounds[0] for a in mesh.actuators], float)
    hi = np.array([a.bounds[1] for a in mesh.actuators], float)
    na = len(lo)
    c = np.ones(na) if initial is None else np.clip(np.asarray(initial, float), lo, hi)
    obj = _Objective(solver, [mesh.markers[m] for m in markers], tgt, fk_tol, None)
    cur = initial_fk if initial_fk is not None else obj.fk(c)
    obj.base = cur
    J = obj.value(cur)
    history = [np.sqrt(J)]
    it = 0
    while np.sqrt(J) > lam and it < i_max:
        it += 1
        obj.base = cur
        obj.dx = None
        p0 = cur.positions[obj.markers].ravel()
        K = np.zeros((p0.size, na))
        if jacobian == 'implicit':
            dx = solver.sensitivity(cur)
            obj.dx = dx
            K = dx[obj.markers].reshape(p0.size, na)
        # Jacobian of the marker positions by (central) differences, eq. 14
        for a in range(na if jacobian == 'central' else 0):
            up, dn = min(c[a] + delta, hi[a]), max(c[a] - delta, lo[a])
            cu, cd = c.copy(), c.copy()
            cu[a], cd[a] = up, dn
            pu = obj.fk(cu).positions[obj.markers].ravel() if up != c[a] else p0
            pd = obj.fk(cd).positions[obj.markers].ravel() if dn != c[a] else p0
            if up - dn > 0:
                K[:, a] = (pu - pd) / (up - dn)
        r = p0 - tgt.ravel()
        grad = 2.0 * K.T @ r
        if direction == 'gradient':
            d = -grad
        else:
            KtK = K.T @ K
            mu = 1e-3 * np.trace(KtK) / na + 1e-12  # Levenberg-Marquardt damping
            d = -np.linalg.solve(KtK + mu * np.eye(na), K.T @ r)
        # keep the direction feasible at active bounds
        d[(c <= lo) & (d < 0)] = 0.0
        d[(c >= hi) & (d > 0)] = 0.0
        if not np.any(d):
            break

        def trial(h):
            cc = np.clip(c + h * d, lo, hi)
            res = obj.fk(cc)
            return obj.value(res), cc, res

        # soft line search, eq. 15: shrinking ...
        dh = 1.0
        J_new, c_new, res_new = trial(dh)
        k = 0
        while J_new >= J and k < max_shrink:
            dh *= tau
            J_new, c_new, res_new = trial(dh)
            k += 1
        if J_new >= J:
            break  # no decrease along d: a local minimum of eq. 12 (within the bounds)
        # ... then expanding
        h, J_opt, c_opt, res_opt = dh, J_new, c_new, res_new
        for _ in range(max_expand):
            if np.all(np.clip(c + (h + dh) * d, lo, hi) == c_opt):
                break
            J_try, c_try, res_try = trial(h + dh)
            if J_try <= J_opt:
                h, J_opt, c_opt, res_opt = h + dh, J_try, c_try, res_try
            else:
                break
        c, J, cur = c_opt, J_opt, res_opt
        history.append(np.sqrt(J))
    err = float(np.sqrt(J))
    return IKResult(actuation=c, reached=cur.positions[obj.markers].copy(), target=tgt, error=err,
                    iterations=it, fk_solves=obj.n, success=err <= lam, out_of_reach=err > lam, fk=cur,
                    history=np.asarray(history))
