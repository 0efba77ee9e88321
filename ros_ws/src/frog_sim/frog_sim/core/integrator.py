"""Implicit (backward) Euler time stepping solved by Newton (paper eq. 6-8).

Residual (eq. 6), with ``v = (x - x_k) / h``::

    F(x) = M (x - x_k - h v_k) / h^2 + dE/dx(x) - f_d(x, v) - f_ext

Jacobian (eq. 8)::

    J = M / h^2 + d2E/dx2 - df_d/dx - (1/h) df_d/dv

``f_ext`` holds the constant applied force plus the lumped rigid-body damping of
:mod:`~frog_sim.core.body_damping`, evaluated at the start of each step (explicit).

Newton (eq. 7) iterates ``x <- x - J \\ F`` from the predictor ``x_k + h v_k`` until
``max|F| <= force_tolerance`` or ``max|dx| <= position_tolerance``; at most
``max_iterations``. A step that does not converge (or produces a non-finite value) is
retried as two half steps, recursively up to ``max_halvings`` times; if that fails a
:class:`ConvergenceError` names the time, step size and residual. A step never
returns NaN or an unconverged state.

The whole loop (actuation update, assembly, sparse LU, Newton, state update) runs in
numba for speed; a SuperLU (scipy.sparse CSR) path is used when the pivot test of the
unpivoted numba sparse LU fails, or on request (``solver='superlu'``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse.linalg as spla
from numba import njit

from .actuation import ActuatorArrays, apply_actuation
from .body_damping import body_damping_force
from .elastic_energy import bend_element, stretch_element
from .fluid import drag_element, drag_prefactors
from .linear_algebra import build_jacobian_pattern, sparse_lu_factor, sparse_lu_pack, sparse_lu_substitute

STATUS_OK = 0
STATUS_MAX_ITER = 1
STATUS_BAD_PIVOT = 2
STATUS_NOT_FINITE = 3
_STATUS_TEXT = {STATUS_MAX_ITER: 'Newton did not converge within the iteration limit',
                STATUS_BAD_PIVOT: 'tiny pivot in the LU factorisation',
                STATUS_NOT_FINITE: 'non-finite residual or update'}


class ConvergenceError(RuntimeError):
    """A time step failed even after the allowed number of step halvings."""


@njit(cache=True, error_model='numpy')
def assemble_system(x, x_prev, v_prev, h, mass2, edges, rest, ea, bends, bend_len, ei, kappa0,
                    cn, ct, f_ext, fixed, edge_map, bend_map, diag_map, dynamic, data, resid,
                    want_jac=True):
    """Residual (eq. 6) into ``resid`` (2N,) and Jacobian (eq. 8) scattered into ``data``.

    ``dynamic=False`` assembles the static problem ``dE/dx - f_ext = 0`` (no inertia, no
    drag). Rows/columns of ``fixed`` DOFs are replaced by the identity: the element maps
    send their entries to a trash slot (the last entry of ``data``). With
    ``want_jac=False`` only the residual is computed. Returns the max-norm of the
    residual over free DOFs [N].
    """
    n = x.shape[0]
    if want_jac:
        for k in range(data.shape[0]):
            data[k] = 0.0
    inv_h = 1.0 / h
    inv_h2 = inv_h * inv_h
    for d in range(n):
        if dynamic:
            resid[d] = mass2[d] * (x[d] - x_prev[d] - h * v_prev[d]) * inv_h2 - f_ext[d]
            if want_jac and not fixed[d]:
                data[diag_map[d]] += mass2[d] * inv_h2
        else:
            resid[d] = -f_ext[d]
    g4 = np.empty(4)
    h4 = np.empty((4, 4))
    g6 = np.empty(6)
    h6 = np.empty((6, 6))
    work = np.empty((3, 4, 4))
    jv = np.empty((4, 4))
    jx = np.empty((4, 4))
    dof4 = np.empty(4, dtype=np.int64)
    dof6 = np.empty(6, dtype=np.int64)
    for m in range(edges.shape[0]):
        a = edges[m, 0]
        b = edges[m, 1]
        dof4[0] = 2 * a
        dof4[1] = 2 * a + 1
        dof4[2] = 2 * b
        dof4[3] = 2 * b + 1
        stretch_element(x[dof4[0]], x[dof4[1]], x[dof4[2]], x[dof4[3]], rest[m], ea[m], g4, h4,
                        want_jac)
        if dynamic:
            va0 = (x[dof4[0]] - x_prev[dof4[0]]) * inv_h
            va1 = (x[dof4[1]] - x_prev[dof4[1]]) * inv_h
            vb0 = (x[dof4[2]] - x_prev[dof4[2]]) * inv_h
            vb1 = (x[dof4[3]] - x_prev[dof4[3]]) * inv_h
            drag_element(x[dof4[0]], x[dof4[1]], x[dof4[2]], x[dof4[3]], va0, va1, vb0, vb1,
                         cn[m], ct[m], g6, jv, jx, want_jac)
            for p in range(4):
                g4[p] -= g6[p]
                if want_jac:
                    for q in range(4):
                        h4[p, q] -= jx[p, q] + jv[p, q] * inv_h
        for p in range(4):
            resid[dof4[p]] += g4[p]
        if want_jac:
            for p in range(4):
                for q in range(4):
                    data[edge_map[m, p, q]] += h4[p, q]
    for m in range(bends.shape[0]):
        for r in range(3):
            dof6[2 * r] = 2 * bends[m, r]
            dof6[2 * r + 1] = 2 * bends[m, r] + 1
        bend_element(x[dof6[0]], x[dof6[1]], x[dof6[2]], x[dof6[3]], x[dof6[4]], x[dof6[5]],
                     bend_len[m], ei[m], kappa0[m], g6, h6, work, want_jac)
        for p in range(6):
            resid[dof6[p]] += g6[p]
        if want_jac:
            for p in range(6):
                for q in range(6):
                    data[bend_map[m, p, q]] += h6[p, q]
    norm = 0.0
    for d in range(n):
        if fixed[d]:
            resid[d] = 0.0
            if want_jac:
                data[diag_map[d]] = 1.0
        else:
            a = abs(resid[d])
            if not np.isfinite(resid[d]):
                return np.inf
            if a > norm:
                norm = a
    return norm


@njit(cache=True, error_model='numpy')
def newton_direct(x, x_prev, v_prev, h, mass2, edges, rest, ea, bends, bend_len, ei, kappa0,
                  cn, ct, f_ext, fixed, edge_map, bend_map, diag_map, perm, plan, dynamic,
                  force_tol, pos_tol, max_iter, lu, rhs, resid, lu_state, reuse, packed,
                  refresh_ratio=0.5):
    """Newton iterations (eq. 7) with the numba sparse LU; ``x`` holds the guess and result.

    ``plan`` = (diag, low_ptr, low_row, low_idx, up_ptr, up_col, up_idx, op_ptr,
    op_target) of a :class:`~frog_sim.core.linear_algebra.SparseLUPlan`.
    With ``reuse`` the LU factors kept in ``lu`` (valid when ``lu_state[0] == 1``) are
    reused across iterations and steps (simplified Newton); the Jacobian is
    re-assembled and re-factorised as soon as the residual contracts by less than
    ``1 / refresh_ratio`` per iteration. Convergence: ``max|F| <= force_tol``, or a full Newton
    update (fresh Jacobian) with ``max|dx| <= pos_tol``. ``lu_state[1]`` counts
    factorisations. Returns (status, iterations, residual norm).
    """
    n = x.shape[0]
    diag, low_ptr, low_row, low_idx, up_ptr, up_col, up_idx, op_ptr, op_t = plan
    norm = np.inf
    prev = np.inf
    x_last = x.copy()      # iterate before the last update (to undo a bad simplified step)
    last_fresh = True      # was the last update a full Newton step?
    for it in range(max_iter):
        if not reuse:
            lu_state[0] = 0
        fresh = lu_state[0] == 0
        norm = assemble_system(x, x_prev, v_prev, h, mass2, edges, rest, ea, bends, bend_len,
                               ei, kappa0, cn, ct, f_ext, fixed, edge_map, bend_map, diag_map,
                               dynamic, lu, resid, False)
        if norm <= force_tol:
            return STATUS_OK, it, norm
        if not fresh and not (norm <= refresh_ratio * prev):
            fresh = True
            if not last_fresh:
                # a simplified step (old factors) contracted too little or diverged: go back
                # to the previous iterate and take a full Newton step from there
                for d in range(n):
                    x[d] = x_last[d]
                norm = prev
        if not np.isfinite(norm):
            lu_state[0] = 0
            return STATUS_NOT_FINITE, it, norm
        if fresh:
            assemble_system(x, x_prev, v_prev, h, mass2, edges, rest, ea, bends, bend_len, ei,
                            kappa0, cn, ct, f_ext, fixed, edge_map, bend_map, diag_map, dynamic,
                            lu, resid, True)
            st = sparse_lu_factor(lu, diag, low_ptr, low_idx, up_ptr, up_idx, op_ptr, op_t, 1e-13)
            lu_state[1] += 1
            if st != 0:
                lu_state[0] = 0
                return STATUS_BAD_PIVOT, it, norm
            sparse_lu_pack(lu, diag, low_idx, up_idx, packed)
            lu_state[0] = 1
        prev = norm
        last_fresh = fresh
        for i in range(n):
            rhs[i] = resid[perm[i]]
            x_last[i] = x[i]
        sparse_lu_substitute(packed, rhs, low_ptr, low_row, up_ptr, up_col)
        step = 0.0
        for i in range(n):
            dx = rhs[i]
            if not np.isfinite(dx):
                lu_state[0] = 0
                return STATUS_NOT_FINITE, it, norm
            x[perm[i]] -= dx
            if abs(dx) > step:
                step = abs(dx)
        if fresh and step <= pos_tol:
            return STATUS_OK, it + 1, norm
    lu_state[0] = 0
    return STATUS_MAX_ITER, max_iter, norm


@njit(cache=True, error_model='numpy')
def run_direct(n_steps, t, h, x, v, mass2, edges, rest, ea, bends, bend_len, ei, kappa0, cn, ct,
               f_ext, fixed, edge_map, bend_map, diag_map, perm, plan, force_tol, pos_tol,
               max_iter, act_profile, act_young, act_times, act_offsets, act_bend, act_bend_limb,
               act_bend_sign, act_bend_i, act_edge, act_edge_limb, act_edge_area, act_root,
               act_root_limb, act_root_sign, act_root_base, act_root_half, act_root_len,
               act_root_i, lu, rhs, resid, x_prev, v_prev, lu_state, reuse, v_old, packed, bd_mass, bd_ref,
               bd_coef, f_tot, f_damp, refresh_ratio=0.5):
    """Advance ``n_steps`` steps of size ``h`` in place (x, v), actuation included.

    The Newton guess extrapolates the velocity linearly, ``x_k + h (2 v_k - v_{k-1})``
    (``v_old`` holds v_{k-1} and is updated), which saves about one iteration per step.

    ``bd_coef`` = (X_u, Y_v, N_r) of the lumped body damping (all 0: none); ``f_tot``
    and ``f_damp`` are work arrays (2N,).

    Returns (steps done, status of the failing step or 0, total Newton iterations,
    last residual norm). On failure x, v hold the state before the failing step.
    """
    n = x.shape[0]
    total_iter = 0
    norm = 0.0
    damp = bd_coef[0] != 0.0 or bd_coef[1] != 0.0 or bd_coef[2] != 0.0
    for d in range(n):
        f_tot[d] = f_ext[d]
    for k in range(n_steps):
        t_new = t + (k + 1) * h
        apply_actuation(t_new, act_profile, act_young, act_times, act_offsets, act_bend,
                        act_bend_limb, act_bend_sign, act_bend_i, act_edge, act_edge_limb,
                        act_edge_area, act_root, act_root_limb, act_root_sign, act_root_base,
                        act_root_half, act_root_len, act_root_i, kappa0, ei, ea)
        if damp:
            body_damping_force(x, v, bd_mass, bd_ref, bd_coef[0], bd_coef[1], bd_coef[2], f_damp)
            for d in range(n):
                f_tot[d] = f_ext[d] + (0.0 if fixed[d] else f_damp[d])
        for d in range(n):
            x_prev[d] = x[d]
            v_prev[d] = v[d]
            if not fixed[d]:
                x[d] = x[d] + h * (2.0 * v[d] - v_old[d])
        status, iters, norm = newton_direct(
            x, x_prev, v_prev, h, mass2, edges, rest, ea, bends, bend_len, ei, kappa0, cn, ct,
            f_tot, fixed, edge_map, bend_map, diag_map, perm, plan, True, force_tol, pos_tol,
            max_iter, lu, rhs, resid, lu_state, reuse, packed, refresh_ratio)
        total_iter += iters
        if status != 0:
            for d in range(n):
                x[d] = x_prev[d]
                v[d] = v_prev[d]
            return k, status, total_iter, norm
        for d in range(n):
            v[d] = (x[d] - x_prev[d]) / h if not fixed[d] else 0.0
            v_old[d] = v_prev[d]
    return n_steps, 0, total_iter, norm


@dataclass
class StepStatistics:
    """Counters of the solver since construction (for diagnostics)."""

    steps: int = 0
    newton_iterations: int = 0
    halvings: int = 0
    sparse_fallbacks: int = 0
    last_residual: float = 0.0


class ImplicitEulerIntegrator:
    """Backward-Euler/Newton integrator of a :class:`~frog_sim.core.rod_network.RodNetwork`.

    Parameters
    ----------
    network : RodNetwork
    mass : ndarray, shape (N,)
        Revised lumped masses incl. added mass [kg] (eq. 4).
    fluid_density : float
        rho_f [kg/m^3] for the drag prefactors (0 disables drag).
    actuator : ActuatorArrays, optional
        Actuated limb elements; ``None`` for a passive network.
    fixed_dofs : array-like of int, optional
        Clamped degrees of freedom (index ``2*node + component``).
    solver : {'direct', 'superlu'}
        Numba sparse LU with a precomputed minimum-degree plan (default) or scipy
        SuperLU on the CSR Jacobian (reference path, also the automatic fallback).
    force_tolerance : float
        Newton residual tolerance max|F| [N].
    position_tolerance : float
        Newton also stops when max|dx| <= this [m] (update at round-off level).
    max_iterations : int
        Newton iterations per attempt.
    max_halvings : int
        Recursive step halvings before :class:`ConvergenceError`.
    reuse_jacobian : bool
        Keep the LU factors across Newton iterations and steps while the residual
        contracts fast (simplified Newton); re-factorise otherwise. Same converged
        result (residual test), fewer factorisations.
    body_damping : (float, float, float)
        Linear damping (X_u [N s/m], Y_v [N s/m], N_r [N m s/rad]) lumped on the rigid
        body (:mod:`~frog_sim.core.body_damping`); zeros: none.
    reference : ndarray, shape (N, 2), optional
        Reference pose centred at its COM (the body axes of surge and sway); default: the
        network's positions about their centre of mass.

    Attributes
    ----------
    x, v : ndarray, shape (2N,)
        Positions [m] and velocities [m/s], ordered x0, y0, x1, y1, ...
    time : float
        [s]
    external_force : ndarray, shape (2N,)
        Constant applied force [N] (default zero).
    """

    def __init__(self, network, mass, *, fluid_density=1000.0, actuator=None, fixed_dofs=(),
                 solver='direct', force_tolerance=1e-9, position_tolerance=1e-11,
                 max_iterations=25, max_halvings=8, reuse_jacobian=True, body_damping=(0.0, 0.0, 0.0),
                 reference=None):
        if solver not in ('direct', 'superlu'):
            raise ValueError(f"solver = {solver!r}, expected 'direct' or 'superlu'")
        mass = np.asarray(mass, dtype=float)
        if mass.shape != (network.n_nodes,) or np.any(mass <= 0) or not np.all(np.isfinite(mass)):
            raise ValueError(f'mass must be {network.n_nodes} positive finite values')
        if fluid_density < 0:
            raise ValueError(f'fluid_density = {fluid_density} must be >= 0')
        self.network = network
        self.solver = solver
        self.force_tolerance = float(force_tolerance)
        self.position_tolerance = float(position_tolerance)
        self.max_iterations = int(max_iterations)
        self.max_halvings = int(max_halvings)
        self.mass = mass
        self.mass2 = np.repeat(mass, 2)
        self.cn, self.ct = drag_prefactors(network, fluid_density)
        self.actuator = actuator if actuator is not None else ActuatorArrays.empty()
        self.fixed = np.zeros(network.n_dof, dtype=np.bool_)
        fixed_dofs = np.asarray(fixed_dofs, dtype=np.int64)
        if fixed_dofs.size and (fixed_dofs.min() < 0 or fixed_dofs.max() >= network.n_dof):
            raise ValueError(f'fixed DOF {fixed_dofs.max()} out of range 0-{network.n_dof - 1}')
        self.fixed[fixed_dofs] = True
        self.pattern = build_jacobian_pattern(network.n_nodes, network.edges, network.bends)
        n = network.n_dof
        plan = self.pattern.lu_plan
        self._lu = np.zeros(plan.nnz + 1)            # last entry: trash slot of fixed DOFs
        self._packed = np.zeros(plan.low_idx.size + plan.up_idx.size + plan.n)
        self._csr_data = np.zeros(self.pattern.nnz + 1)
        self._maps_lu = self._masked_maps(self.pattern.edge_map_lu, self.pattern.bend_map_lu,
                                          self.pattern.diag_map_lu, plan.nnz)
        self._maps_csr = self._masked_maps(self.pattern.edge_map_csr, self.pattern.bend_map_csr,
                                           self.pattern.diag_map_csr, self.pattern.nnz)
        self._plan = (plan.diag, plan.low_ptr, plan.low_row, plan.low_idx, plan.up_ptr,
                      plan.up_col, plan.up_idx, plan.op_ptr, plan.op_target)
        self.reuse_jacobian = bool(reuse_jacobian)
        self.refresh_ratio = 0.5    # refresh the Jacobian when |F| contracts less than 2x
        self._lu_state = np.zeros(2, dtype=np.int64)   # [factors valid, factorisations]
        self._lu_h = None
        self._rhs = np.zeros(n)
        self._resid = np.zeros(n)
        self._x_prev = np.zeros(n)
        self._v_prev = np.zeros(n)
        self.kappa0 = network.bend_natural_curvature.copy()
        self.ei = network.bend_stiffness.copy()
        self.ea = network.edge_stretching_stiffness.copy()
        self.external_force = np.zeros(n)
        coef = np.asarray(body_damping, dtype=float)
        if coef.shape != (3,) or not np.all(np.isfinite(coef)) or np.any(coef < 0):
            raise ValueError(f'body_damping = {body_damping!r}, expected three finite values >= 0')
        self.body_damping = coef
        pos = network.positions.astype(float)
        if reference is None:
            reference = pos - mass @ pos / mass.sum()
        self.reference = np.ascontiguousarray(reference, dtype=float)
        if self.reference.shape != (network.n_nodes, 2):
            raise ValueError(f'reference has shape {self.reference.shape}, expected ({network.n_nodes}, 2)')
        self._f_tot = np.zeros(n)
        self._f_damp = np.zeros(n)
        self.x = network.positions.reshape(-1).astype(float).copy()
        self.v = np.zeros(n)
        self._v_old = np.zeros(n)      # velocity of the previous step (predictor)
        self.time = 0.0
        self.stats = StepStatistics()
        self.update_actuation(self.time)

    def _masked_maps(self, edge_map, bend_map, diag_map, trash):
        """Copies of the element maps with rows/columns of fixed DOFs sent to ``trash``."""
        net = self.network
        edof = np.repeat(2 * net.edges, 2, axis=1) + np.tile([0, 1], 2)
        bdof = np.repeat(2 * net.bends, 2, axis=1) + np.tile([0, 1], 3)
        em = edge_map.astype(np.int32)
        bm = bend_map.astype(np.int32)
        fe = self.fixed[edof]
        fb = self.fixed[bdof]
        em[fe[:, :, None] | fe[:, None, :]] = trash
        bm[fb[:, :, None] | fb[:, None, :]] = trash
        return em, bm, diag_map.astype(np.int32)

    def set_state(self, x=None, v=None) -> None:
        """Overwrite positions (2N,) [m] and/or velocities (2N,) [m/s]; resets the predictor."""
        if x is not None:
            x = np.asarray(x, dtype=float).ravel()
            if x.shape != self.x.shape or not np.all(np.isfinite(x)):
                raise ValueError(f'x must be {self.x.size} finite values')
            self.x[:] = x
        if v is not None:
            v = np.asarray(v, dtype=float).ravel()
            if v.shape != self.v.shape or not np.all(np.isfinite(v)):
                raise ValueError(f'v must be {self.v.size} finite values')
            self.v[:] = v
        self._v_old[:] = self.v
        self._lu_state[0] = 0

    @property
    def factorizations(self) -> int:
        """Number of LU factorisations so far (Jacobian refreshes)."""
        return int(self._lu_state[1])

    # ------------------------------------------------------------------ helpers
    def update_actuation(self, t: float) -> None:
        """Set natural curvature and stiffness of actuated elements for time ``t``."""
        apply_actuation(float(t), *self.actuator.as_tuple(), self.kappa0, self.ei, self.ea)

    def applied_force(self) -> np.ndarray:
        """Force of the next step, held over it [N]: ``external_force`` plus the body damping
        at the current state."""
        if not np.any(self.body_damping):
            return self.external_force
        body_damping_force(self.x, self.v, self.mass, self.reference, *self.body_damping, self._f_damp)
        return self.external_force + np.where(self.fixed, 0.0, self._f_damp)

    def _assemble(self, x, x_prev, v_prev, h, dynamic, data, edge_map, bend_map, diag_map, f_ext=None):
        return assemble_system(x, x_prev, v_prev, h, self.mass2, self.network.edges,
                               self.network.edge_rest_length, self.ea, self.network.bends,
                               self.network.bend_length, self.ei, self.kappa0, self.cn, self.ct,
                               self.external_force if f_ext is None else f_ext, self.fixed, edge_map,
                               bend_map, diag_map, dynamic, data, self._resid)

    def _newton_sparse(self, x, x_prev, v_prev, h, dynamic, f_ext):
        """Newton with SuperLU on the CSR Jacobian (robust path)."""
        pat = self.pattern
        norm = np.inf
        for it in range(self.max_iterations):
            norm = self._assemble(x, x_prev, v_prev, h, dynamic, self._csr_data, *self._maps_csr, f_ext=f_ext)
            if not np.isfinite(norm):
                return STATUS_NOT_FINITE, it, norm
            if norm <= self.force_tolerance:
                return STATUS_OK, it, norm
            try:
                dx = spla.spsolve(pat.csr(self._csr_data[:-1]).tocsc(), self._resid)
            except RuntimeError:
                return STATUS_BAD_PIVOT, it, norm
            if not np.all(np.isfinite(dx)):
                return STATUS_NOT_FINITE, it, norm
            x -= dx
            if np.max(np.abs(dx)) <= self.position_tolerance:
                return STATUS_OK, it + 1, norm
        return STATUS_MAX_ITER, self.max_iterations, norm

    def _newton(self, x, x_prev, v_prev, h, dynamic, solver, f_ext=None):
        pat = self.pattern
        f_ext = self.external_force if f_ext is None else f_ext
        if solver == 'direct':
            reuse = self.reuse_jacobian and dynamic
            if not reuse or self._lu_h != h:
                self._lu_state[0] = 0
            self._lu_h = h if reuse else None
            status, iters, norm = newton_direct(
                x, x_prev, v_prev, h, self.mass2, self.network.edges,
                self.network.edge_rest_length, self.ea, self.network.bends,
                self.network.bend_length, self.ei, self.kappa0, self.cn, self.ct,
                f_ext, self.fixed, *self._maps_lu, pat.lu_plan.perm, self._plan,
                dynamic, self.force_tolerance,
                self.position_tolerance, self.max_iterations, self._lu, self._rhs, self._resid,
                self._lu_state, reuse, self._packed, self.refresh_ratio)
            if status != STATUS_BAD_PIVOT:
                return status, iters, norm
            self.stats.sparse_fallbacks += 1
        return self._newton_sparse(x, x_prev, v_prev, h, dynamic, f_ext)

    def _single_step(self, h, solver):
        """One backward-Euler step of size h from (x, v, time); returns (status, iters, norm)."""
        t_new = self.time + h
        self.update_actuation(t_new)
        f_ext = self.applied_force()
        x_prev = self.x.copy()
        v_prev = self.v.copy()
        x = x_prev + np.where(self.fixed, 0.0, h * (2.0 * v_prev - self._v_old))
        status, iters, norm = self._newton(x, x_prev, v_prev, h, True, solver, f_ext)
        if status == STATUS_OK:
            self.x = x
            self.v = np.where(self.fixed, 0.0, (x - x_prev) / h)
            self._v_old = v_prev
            self.time = t_new
        return status, iters, norm

    def _robust_step(self, h, depth=0):
        status, iters, norm = self._single_step(h, self.solver)
        self.stats.newton_iterations += iters
        self.stats.last_residual = norm
        if status == STATUS_OK:
            return
        if self.reuse_jacobian:
            # simplified Newton failed: retry the same step with full Newton first
            self.reuse_jacobian = False
            try:
                status, iters, norm = self._single_step(h, self.solver)
            finally:
                self.reuse_jacobian = True
            self.stats.newton_iterations += iters
            self.stats.last_residual = norm
            if status == STATUS_OK:
                return
        if depth >= self.max_halvings:
            raise ConvergenceError(
                f'time step failed at t = {self.time:.6g} s with h = {h:.3g} s after '
                f'{depth} halvings: {_STATUS_TEXT.get(status, status)} '
                f'(residual {norm:.3g} N, tolerance {self.force_tolerance:.3g} N)')
        self.stats.halvings += 1
        self._robust_step(0.5 * h, depth + 1)
        self._robust_step(0.5 * h, depth + 1)

    # ------------------------------------------------------------------ public API
    def step(self, h: float) -> None:
        """Advance one step of size ``h`` [s] (with halving fallback).

        Raises
        ------
        ValueError
            If ``h`` is not a positive finite number.
        ConvergenceError
            If the step cannot be completed after ``max_halvings`` halvings; the state is
            then the last converged (sub-)step, never a partial Newton iterate.
        """
        if not (np.isfinite(h) and h > 0):
            raise ValueError(f'time step h = {h!r} must be a positive finite number of seconds')
        self._robust_step(float(h))
        self.stats.steps += 1

    def advance(self, n_steps: int, h: float) -> None:
        """Advance ``n_steps`` steps of size ``h`` [s]; the fast path runs in numba.

        Raises
        ------
        ValueError, ConvergenceError
            As :meth:`step`.
        """
        if not (np.isfinite(h) and h > 0):
            raise ValueError(f'time step h = {h!r} must be a positive finite number of seconds')
        n_steps = int(n_steps)
        if n_steps < 0:
            raise ValueError(f'n_steps = {n_steps} must be >= 0')
        if self.solver != 'direct':
            for _ in range(n_steps):
                self.step(h)
            return
        pat = self.pattern
        act = self.actuator.as_tuple()
        if not self.reuse_jacobian or self._lu_h != h:
            self._lu_state[0] = 0
        self._lu_h = h if self.reuse_jacobian else None
        remaining = n_steps
        t0 = self.time
        done_total = 0
        while remaining > 0:
            done, status, iters, norm = run_direct(
                remaining, t0 + done_total * h, h, self.x, self.v,
                self.mass2, self.network.edges, self.network.edge_rest_length, self.ea,
                self.network.bends, self.network.bend_length, self.ei, self.kappa0, self.cn,
                self.ct, self.external_force, self.fixed, *self._maps_lu, pat.lu_plan.perm,
                self._plan, self.force_tolerance,
                self.position_tolerance, self.max_iterations, *act, self._lu, self._rhs,
                self._resid, self._x_prev, self._v_prev, self._lu_state, self.reuse_jacobian,
                self._v_old, self._packed, self.mass, self.reference, self.body_damping, self._f_tot,
                self._f_damp, self.refresh_ratio)
            self.stats.newton_iterations += iters
            self.stats.last_residual = norm
            self.stats.steps += done
            done_total += done
            remaining -= done
            self.time = t0 + done_total * h
            if status != STATUS_OK:
                # retry the failing step robustly (halving / SuperLU), then continue fast
                self._lu_state[0] = 0
                self._robust_step(h)
                if self._lu_h != h:
                    self._lu_state[0] = 0
                    self._lu_h = h if self.reuse_jacobian else None
                self.stats.steps += 1
                done_total += 1
                remaining -= 1
                self.time = t0 + done_total * h
        self.update_actuation(self.time)

    def solve_static(self, load_steps: int = 1) -> int:
        """Solve the static equilibrium ``dE/dx = f_ext`` from the current ``x``.

        The external force is ramped in ``load_steps`` equal increments (continuation
        for large deflections). Velocities are set to zero.

        Returns
        -------
        int
            Total Newton iterations.

        Raises
        ------
        ConvergenceError
            If an increment does not converge.
        """
        full = self.external_force.copy()
        total = 0
        try:
            for k in range(1, int(load_steps) + 1):
                self.external_force = full * (k / load_steps)
                status, iters, norm = self._newton(self.x, self.x, self.v, 1.0, False, self.solver)
                total += iters
                if status != STATUS_OK:
                    raise ConvergenceError(
                        f'static solve failed at load increment {k}/{load_steps}: '
                        f'{_STATUS_TEXT.get(status, status)} (residual {norm:.3g} N)')
        finally:
            self.external_force = full
        self.v[:] = 0.0
        return total

    def internal_force(self, x=None) -> np.ndarray:
        """Elastic force ``-dE/dx`` (2N,) [N] at ``x`` (default: current state)."""
        x = self.x if x is None else np.ascontiguousarray(x, dtype=float)
        data = np.zeros(self.pattern.nnz + 1)
        saved = self.external_force
        self.external_force = np.zeros_like(saved)
        fixed = self.fixed
        self.fixed = np.zeros_like(fixed)
        try:
            self._assemble(x, x, self.v, 1.0, False, data, *self._maps_csr)
        finally:
            self.external_force = saved
            self.fixed = fixed
        return -self._resid.copy()
