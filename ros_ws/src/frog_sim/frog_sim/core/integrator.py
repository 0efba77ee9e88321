"""Implicit (backward) Euler time stepping solved by Newton (paper eq. 6-8).

Residual (eq. 6), with ``v = (x - x_k) / h``::

    F(x) = M (x - x_k - h v_k) / h^2 + dE/dx(x) - f_d(x, v) - f_ext

Jacobian (eq. 8)::

    J = M / h^2 + d2E/dx2 - df_d/dx - (1/h) df_d/dv

The energy and force terms are element sets (:mod:`~frog_sim.core.element_sets`): a DOF
map plus a numba kernel per term, listed in ``ImplicitEulerIntegrator._element_sets``
(implicit, inside Newton: stretching E_s and drag f_d on the edges, bending E_b on the
bend triples) and ``ImplicitEulerIntegrator._explicit_sets`` (lagged: the lumped
rigid-body damping of :mod:`~frog_sim.core.body_damping` and the waterline friction of
:mod:`~frog_sim.core.waterline_friction`, evaluated at the start of each step and added to
``f_ext``, the constant applied force). The inertia term (lumped
masses M of eq. 4) belongs to the step itself.

Newton (eq. 7) iterates ``x <- x - J \\ F`` from the predictor ``x_k + h v_k`` until
``max|F| <= force_tolerance`` or ``max|dx| <= position_tolerance``; at most
``max_iterations``. A step that does not converge (or produces a non-finite value) is
retried as two half steps, recursively up to ``max_halvings`` times; if that fails a
:class:`ConvergenceError` names the time, step size and residual. A step never
returns NaN or an unconverged state.

The whole loop (actuation update, explicit terms, assembly, sparse LU, Newton, state
update) runs in numba on four packed arguments: the :class:`System` (masses, fixed DOFs,
element sets, actuator arrays), the :class:`Solver` (LU plan, tolerances), the
:class:`Workspace` (LU values, right-hand side, residual, work arrays) and the
:class:`State` (x, v, start of the step, predictor, time). :func:`step_direct` is the
one step: :func:`run_direct` (the fast path of ``advance``) loops over it and the
step-halving path (``step``) calls it per (sub-)step. A SuperLU (scipy.sparse CSR) path is
used when the pivot test of the unpivoted numba sparse LU fails, or on request
(``solver='superlu``); it runs the same :func:`begin_step`, :func:`assemble_system` and
:func:`end_step` around SuperLU.
"""
from __future__ import annotations

from collections import namedtuple
from dataclasses import dataclass

import numpy as np
import scipy.sparse.linalg as spla
from numba import literal_unroll, njit

from .actuation import ActuatorArrays, update_actuators
from .body_damping import BodyDampingTerm
from .waterline_friction import WaterlineFrictionTerm
from .elastic_energy import BendTerm, StretchTerm
from .element_sets import ElementSet, ExplicitSet, add_explicit_set, assemble_element_set, scatter_maps
from .fluid import DragTerm, drag_prefactors
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


System = namedtuple('System', 'mass2 fixed diag_maps element_sets explicit_sets actuator kappa0 ei ea')
System.__doc__ = """What the equations of motion are made of, for the numba step.

mass2 (2N,) lumped masses per DOF [kg] (eq. 4); fixed (2N,) bool clamped DOFs; diag_maps
(2, 2N) int32 diagonal slots in the LU [0] / CSR [1] values; element_sets: tuple of
:class:`~frog_sim.core.element_sets.ElementSet` (implicit terms: stretch + drag on the
edges, bend on the triples); explicit_sets: tuple of
:class:`~frog_sim.core.element_sets.ExplicitSet` (lagged terms: the body damping);
actuator: ``ActuatorArrays.as_tuple()``; kappa0, ei, ea: the live arrays it writes."""

State = namedtuple('State', 'x v x_prev v_prev v_old time')
State.__doc__ = """Positions x and velocities v (2N,) (updated in place), the start of the current step
x_prev, v_prev, the velocity of the step before v_old (predictor), and time (1,) [s]."""

Solver = namedtuple('Solver', 'perm plan force_tol pos_tol max_iter refresh_ratio')
Solver.__doc__ = """Newton settings and the sparse LU plan: perm (2N,), plan = (diag, low_ptr, low_row,
low_idx, up_ptr, up_col, up_idx, op_ptr, op_target) of a
:class:`~frog_sim.core.linear_algebra.SparseLUPlan`, tolerances [N], [m], iteration
limit and the Jacobian refresh ratio of simplified Newton."""

Workspace = namedtuple('Workspace', 'lu packed rhs resid x_last f_total lu_state')
Workspace.__doc__ = """Work arrays of the numba step: lu (LU values + trash slot), packed factors, rhs,
resid (2N,), the iterate before the last update x_last, the applied force of the step
f_total (2N,), lu_state = [factors valid, factorisations]."""

LU_TARGET = 0
CSR_TARGET = 1


@njit(cache=True, error_model='numpy')
def assemble_system(system, x, x_prev, v_prev, h, f_ext, fixed, target, dynamic, data, resid,
                    want_jac=True):
    """Residual (eq. 6) into ``resid`` (2N,) and Jacobian (eq. 8) scattered into ``data``.

    Inertia ``M (x - x_k - h v_k) / h^2`` and ``-f_ext``, then every element set of
    ``system`` (``target`` 0: LU value array, 1: CSR). ``dynamic=False`` assembles the
    static problem ``dE/dx - f_ext = 0`` (no inertia, no velocity-dependent terms). Rows and
    columns of ``fixed`` DOFs are replaced by the identity: the element maps send their
    entries to a trash slot (the last entry of ``data``). With ``want_jac=False`` only the
    residual is computed. Returns the max-norm of the residual over free DOFs [N].
    """
    n = x.shape[0]
    diag_map = system.diag_maps[target]
    mass2 = system.mass2
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
    for es in literal_unroll(system.element_sets):
        assemble_element_set(es, target, x, x_prev, inv_h, dynamic, resid, data, want_jac)
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
def newton_direct(system, solver, work, x, x_prev, v_prev, f_ext, h, dynamic, reuse):
    """Newton iterations (eq. 7) with the numba sparse LU; ``x`` holds the guess and result.

    With ``reuse`` the LU factors kept in ``work.lu`` (valid when ``work.lu_state[0] == 1``)
    are reused across iterations and steps (simplified Newton); the Jacobian is
    re-assembled and re-factorised as soon as the residual contracts by less than
    ``1 / solver.refresh_ratio`` per iteration. Convergence: ``max|F| <= force_tol``, or a
    full Newton update (fresh Jacobian) with ``max|dx| <= pos_tol``. ``lu_state[1]``
    counts factorisations. Returns (status, iterations, residual norm).
    """
    n = x.shape[0]
    diag, low_ptr, low_row, low_idx, up_ptr, up_col, up_idx, op_ptr, op_t = solver.plan
    perm = solver.perm
    lu = work.lu
    rhs = work.rhs
    resid = work.resid
    lu_state = work.lu_state
    x_last = work.x_last   # iterate before the last update (to undo a bad simplified step)
    fixed = system.fixed
    norm = np.inf
    prev = np.inf
    last_fresh = True      # was the last update a full Newton step?
    for it in range(solver.max_iter):
        if not reuse:
            lu_state[0] = 0
        fresh = lu_state[0] == 0
        norm = assemble_system(system, x, x_prev, v_prev, h, f_ext, fixed, LU_TARGET, dynamic,
                               lu, resid, False)
        if norm <= solver.force_tol:
            return STATUS_OK, it, norm
        if not fresh and not (norm <= solver.refresh_ratio * prev):
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
            assemble_system(system, x, x_prev, v_prev, h, f_ext, fixed, LU_TARGET, dynamic, lu,
                            resid, True)
            st = sparse_lu_factor(lu, diag, low_ptr, low_idx, up_ptr, up_idx, op_ptr, op_t, 1e-13)
            lu_state[1] += 1
            if st != 0:
                lu_state[0] = 0
                return STATUS_BAD_PIVOT, it, norm
            sparse_lu_pack(lu, diag, low_idx, up_idx, work.packed)
            lu_state[0] = 1
        prev = norm
        last_fresh = fresh
        for i in range(n):
            rhs[i] = resid[perm[i]]
            x_last[i] = x[i]
        sparse_lu_substitute(work.packed, rhs, low_ptr, low_row, up_ptr, up_col)
        step = 0.0
        for i in range(n):
            dx = rhs[i]
            if not np.isfinite(dx):
                lu_state[0] = 0
                return STATUS_NOT_FINITE, it, norm
            x[perm[i]] -= dx
            if abs(dx) > step:
                step = abs(dx)
        if fresh and step <= solver.pos_tol:
            return STATUS_OK, it + 1, norm
    lu_state[0] = 0
    return STATUS_MAX_ITER, solver.max_iter, norm


@njit(cache=True, error_model='numpy')
def applied_force(system, x, v, f_ext, out):
    """``out`` = ``f_ext`` plus the forces of every explicit set at (x, v) [N]."""
    for d in range(x.shape[0]):
        out[d] = f_ext[d]
    for es in literal_unroll(system.explicit_sets):
        add_explicit_set(es, x, v, system.fixed, out)


@njit(cache=True, error_model='numpy')
def begin_step(system, state, work, f_ext, t_new, h):
    """Start a step to ``t_new``: actuation at ``t_new``, the applied force (explicit terms
    at the current state) into ``work.f_total``, save (x, v) and set the Newton guess.

    The guess extrapolates the velocity linearly, ``x_k + h (2 v_k - v_{k-1})``, which
    saves about one iteration per step.
    """
    update_actuators(t_new, system.actuator, system.kappa0, system.ei, system.ea)
    x = state.x
    v = state.v
    applied_force(system, x, v, f_ext, work.f_total)
    fixed = system.fixed
    for d in range(x.shape[0]):
        state.x_prev[d] = x[d]
        state.v_prev[d] = v[d]
        if not fixed[d]:
            x[d] = x[d] + h * (2.0 * v[d] - state.v_old[d])


@njit(cache=True, error_model='numpy')
def end_step(system, state, t_new, h):
    """Accept the converged ``state.x``: velocity ``(x - x_k) / h`` (backward Euler), time."""
    fixed = system.fixed
    for d in range(state.x.shape[0]):
        state.v[d] = (state.x[d] - state.x_prev[d]) / h if not fixed[d] else 0.0
        state.v_old[d] = state.v_prev[d]
    state.time[0] = t_new


@njit(cache=True, error_model='numpy')
def undo_step(state):
    """Back to the state at the start of the step (after a failed Newton solve)."""
    for d in range(state.x.shape[0]):
        state.x[d] = state.x_prev[d]
        state.v[d] = state.v_prev[d]


@njit(cache=True, error_model='numpy')
def step_direct(system, solver, work, state, f_ext, t_new, h, reuse):
    """One backward-Euler step to ``t_new`` with the numba sparse LU (the step of both the
    fast and the step-halving paths). On failure the state is left at the last Newton
    iterate (the caller undoes the step or continues with SuperLU).
    Returns (status, iterations, residual norm)."""
    begin_step(system, state, work, f_ext, t_new, h)
    status, iters, norm = newton_direct(system, solver, work, state.x, state.x_prev, state.v_prev,
                                        work.f_total, h, True, reuse)
    if status == STATUS_OK:
        end_step(system, state, t_new, h)
    return status, iters, norm


@njit(cache=True, error_model='numpy')
def run_direct(system, solver, work, state, f_ext, t, h, n_steps, reuse):
    """Advance ``n_steps`` steps of size ``h`` from time ``t`` in place (state.x, state.v).

    Returns (steps done, status of the failing step or 0, total Newton iterations,
    last residual norm). On failure x, v hold the state before the failing step.
    """
    total_iter = 0
    norm = 0.0
    for k in range(n_steps):
        status, iters, norm = step_direct(system, solver, work, state, f_ext, t + (k + 1) * h, h,
                                          reuse)
        total_iter += iters
        if status != STATUS_OK:
            undo_step(state)
            return k, status, total_iter, norm
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
    waterline_friction : (float, float)
        Rate-independent friction (F_c [N], N_c [N m]) against the centre-of-mass velocity and
        the yaw rate (:mod:`~frog_sim.core.waterline_friction`); zeros: none.
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
                 reference=None, waterline_friction=(0.0, 0.0)):
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
        self.reuse_jacobian = bool(reuse_jacobian)
        self.refresh_ratio = 0.5    # refresh the Jacobian when |F| contracts less than 2x
        self._work = Workspace(lu=np.zeros(plan.nnz + 1),            # last entry: trash slot of fixed DOFs
                               packed=np.zeros(plan.low_idx.size + plan.up_idx.size + plan.n),
                               rhs=np.zeros(n), resid=np.zeros(n), x_last=np.zeros(n),
                               f_total=np.zeros(n), lu_state=np.zeros(2, dtype=np.int64))
        self._lu_state = self._work.lu_state   # [factors valid, factorisations]
        self._resid = self._work.resid
        self._lu_h = None
        self._csr_data = np.zeros(self.pattern.nnz + 1)
        self._plan = (plan.diag, plan.low_ptr, plan.low_row, plan.low_idx, plan.up_ptr,
                      plan.up_col, plan.up_idx, plan.op_ptr, plan.op_target)
        pat = self.pattern
        # DOF maps of the element sets and their Jacobian scatter maps (fixed DOFs -> trash)
        self._edge_dofs = np.repeat(2 * network.edges, 2, axis=1) + np.tile([0, 1], 2)
        self._bend_dofs = np.repeat(2 * network.bends, 2, axis=1) + np.tile([0, 1], 3)
        self._edge_maps = scatter_maps(self._edge_dofs, self.fixed, pat.edge_map_csr, pat.edge_map_lu,
                                       plan.nnz, pat.nnz)
        self._bend_maps = scatter_maps(self._bend_dofs, self.fixed, pat.bend_map_csr, pat.bend_map_lu,
                                       plan.nnz, pat.nnz)
        self._diag_maps = np.stack([pat.diag_map_lu, pat.diag_map_csr]).astype(np.int32)
        self._all_dofs = np.arange(n, dtype=np.int64).reshape(1, n)
        self.kappa0 = network.bend_natural_curvature.copy()
        self.ei = network.bend_stiffness.copy()
        self.ea = network.edge_stretching_stiffness.copy()
        self.external_force = np.zeros(n)
        coef = np.asarray(body_damping, dtype=float)
        if coef.shape != (3,) or not np.all(np.isfinite(coef)) or np.any(coef < 0):
            raise ValueError(f'body_damping = {body_damping!r}, expected three finite values >= 0')
        self.body_damping = coef
        coef = np.asarray(waterline_friction, dtype=float)
        if coef.shape != (2,) or not np.all(np.isfinite(coef)) or np.any(coef < 0):
            raise ValueError(f'waterline_friction = {waterline_friction!r}, expected two finite values >= 0')
        self.waterline_friction = coef
        pos = network.positions.astype(float)
        if reference is None:
            reference = pos - mass @ pos / mass.sum()
        self.reference = np.ascontiguousarray(reference, dtype=float)
        if self.reference.shape != (network.n_nodes, 2):
            raise ValueError(f'reference has shape {self.reference.shape}, expected ({network.n_nodes}, 2)')
        self._state = State(x=network.positions.reshape(-1).astype(float).copy(), v=np.zeros(n),
                            x_prev=np.zeros(n), v_prev=np.zeros(n),
                            v_old=np.zeros(n),      # velocity of the previous step (predictor)
                            time=np.zeros(1))
        self.stats = StepStatistics()
        self.update_actuation(self.time)

    # ------------------------------------------------------------------ force/energy terms
    def _element_sets(self):
        """The implicit element sets (inside Newton, eq. 6-8), in assembly order.

        * edges (4 DOFs each): stretching energy E_s (``StretchTerm``: dl, EA) and the
          quadratic drag of eq. 1-2 (``DragTerm``: 1/2 rho C D dl normal / tangent);
        * bends (6 DOFs each): bending energy E_b (``BendTerm``: dl, EI, kappa0).

        A new implicit term is one more record here (on an existing DOF map, or a new
        :class:`~frog_sim.core.element_sets.ElementSet` whose couplings are in the pattern).
        """
        net = self.network
        return (ElementSet(self._edge_dofs, self._edge_maps,
                           (StretchTerm(net.edge_rest_length, self.ea), DragTerm(self.cn, self.ct))),
                ElementSet(self._bend_dofs, self._bend_maps,
                           (BendTerm(net.bend_length, self.ei, self.kappa0),)))

    def _explicit_sets(self):
        """The explicit (lagged) element sets, evaluated at the start of each step and added
        to ``external_force``: the lumped body damping (``BodyDampingTerm``) and the waterline
        friction (``WaterlineFrictionTerm``), one element on all DOFs each (each off while its
        coefficients are zero)."""
        return (ExplicitSet(self._all_dofs, (BodyDampingTerm(self.mass, self.reference, self.body_damping),
                                             WaterlineFrictionTerm(self.mass, self.waterline_friction))),)

    def _system(self):
        """The current :class:`System` (rebuilt per call: picks up rebound attributes)."""
        return System(self.mass2, self.fixed, self._diag_maps, self._element_sets(),
                      self._explicit_sets(), self.actuator.as_tuple(), self.kappa0, self.ei, self.ea)

    def _solver(self):
        return Solver(self.pattern.lu_plan.perm, self._plan, self.force_tolerance,
                      self.position_tolerance, self.max_iterations, self.refresh_ratio)

    # ------------------------------------------------------------------ state
    @property
    def x(self) -> np.ndarray:
        """Positions (2N,) [m], ordered x0, y0, x1, y1, ..."""
        return self._state.x

    @x.setter
    def x(self, value):
        self._state.x[:] = value

    @property
    def v(self) -> np.ndarray:
        """Velocities (2N,) [m/s]."""
        return self._state.v

    @v.setter
    def v(self, value):
        self._state.v[:] = value

    @property
    def time(self) -> float:
        """[s]"""
        return float(self._state.time[0])

    @time.setter
    def time(self, value):
        self._state.time[0] = value

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
        self._state.v_old[:] = self.v
        self._lu_state[0] = 0

    @property
    def factorizations(self) -> int:
        """Number of LU factorisations so far (Jacobian refreshes)."""
        return int(self._lu_state[1])

    # ------------------------------------------------------------------ helpers
    def update_actuation(self, t: float) -> None:
        """Set natural curvature and stiffness of actuated elements for time ``t``."""
        update_actuators(float(t), self.actuator.as_tuple(), self.kappa0, self.ei, self.ea)

    def applied_force(self) -> np.ndarray:
        """Force of the next step, held over it [N]: ``external_force`` plus the explicit
        terms (body damping) at the current state."""
        out = np.empty_like(self.external_force)
        applied_force(self._system(), self.x, self.v, self.external_force, out)
        return out

    def _newton_sparse(self, system, x, x_prev, v_prev, h, dynamic, f_ext):
        """Newton with SuperLU on the CSR Jacobian (robust path)."""
        pat = self.pattern
        norm = np.inf
        for it in range(self.max_iterations):
            norm = assemble_system(system, x, x_prev, v_prev, h, f_ext, self.fixed, CSR_TARGET, dynamic,
                                   self._csr_data, self._resid)
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

    def _direct_reuse(self, h, dynamic):
        """Whether the numba Newton may keep its LU factors (same h, dynamic problem)."""
        reuse = self.reuse_jacobian and dynamic
        if not reuse or self._lu_h != h:
            self._lu_state[0] = 0
        self._lu_h = h if reuse else None
        return reuse

    def _newton(self, x, x_prev, v_prev, h, dynamic, solver, f_ext=None):
        f_ext = self.external_force if f_ext is None else f_ext
        system = self._system()
        if solver == 'direct':
            reuse = self._direct_reuse(h, dynamic)
            status, iters, norm = newton_direct(system, self._solver(), self._work, x, x_prev, v_prev,
                                                f_ext, h, dynamic, reuse)
            if status != STATUS_BAD_PIVOT:
                return status, iters, norm
            self.stats.sparse_fallbacks += 1
        return self._newton_sparse(system, x, x_prev, v_prev, h, dynamic, f_ext)

    def _single_step(self, h, solver):
        """One backward-Euler step of size h from (x, v, time); returns (status, iters, norm).

        The numba step of :meth:`advance` (:func:`step_direct`); with SuperLU (or after a
        bad pivot) the same :func:`begin_step` / :func:`end_step` around SuperLU Newton."""
        t_new = self.time + h
        system = self._system()
        st = self._state
        if solver == 'direct':
            reuse = self._direct_reuse(h, True)
            status, iters, norm = step_direct(system, self._solver(), self._work, st,
                                              self.external_force, t_new, h, reuse)
            if status == STATUS_BAD_PIVOT:
                self.stats.sparse_fallbacks += 1
                status, iters, norm = self._newton_sparse(system, st.x, st.x_prev, st.v_prev, h, True,
                                                          self._work.f_total)
                if status == STATUS_OK:
                    end_step(system, st, t_new, h)
        else:
            begin_step(system, st, self._work, self.external_force, t_new, h)
            status, iters, norm = self._newton_sparse(system, st.x, st.x_prev, st.v_prev, h, True,
                                                      self._work.f_total)
            if status == STATUS_OK:
                end_step(system, st, t_new, h)
        if status == STATUS_OK:
            self.time = t_new
        else:
            undo_step(st)
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
        system = self._system()
        solver = self._solver()
        if not self.reuse_jacobian or self._lu_h != h:
            self._lu_state[0] = 0
        self._lu_h = h if self.reuse_jacobian else None
        remaining = n_steps
        t0 = self.time
        done_total = 0
        while remaining > 0:
            done, status, iters, norm = run_direct(system, solver, self._work, self._state,
                                                   self.external_force, t0 + done_total * h, h,
                                                   remaining, self.reuse_jacobian)
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
        assemble_system(self._system(), x, x, self.v, 1.0, np.zeros_like(self.external_force),
                        np.zeros_like(self.fixed), CSR_TARGET, False, data, self._resid)
        return -self._resid.copy()
