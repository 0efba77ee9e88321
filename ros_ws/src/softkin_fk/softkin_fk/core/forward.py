"""Forward kinematics by local/global energy minimisation (Algorithm 1, eq. 2-10).

:class:`ForwardSolver` precomputes everything that depends only on the rest mesh (centred
rest shapes, element weights c_i = w_i Vol(V_i) of eq. 9, the factorised normal equations of
eq. 10) and then solves for the deformed shape of any actuation vector, optionally warm
started from a previous shape (Algorithm 3).

Actuation elements are penalty targets (weight 5.0, Sec. III-A): every element of an actuator
is given the uniform local ratio that meets eq. 6-8 (the least-norm solution for equal
segments). A stiff body keeps them slightly short of it; ``enforce_constraints=True`` adds a
secant correction of the levels so that eq. 6-8 hold exactly. (Correcting each element's
ratio from its *current* ratio, as Sec. II-D describes, leaves the distribution of closure
among elements undetermined; in our tests it drifted without converging.)

Solvers, all minimising eq. 9:

* ``'local-global'``: Algorithm 1 as printed, optionally with Anderson acceleration kept only
  when a safeguard accepts it (energy does not increase, or the fixed-point residual does not
  grow when the targets depend on the iterate, R_w < 1).
* ``'newton'`` (default when all R_w = 1 and cvxopt is installed): projected Newton with an
  energy line search and a sparse Cholesky of the assembled Hessian (:mod:`.newton`);
  converges in a few iterations from a warm start, and provides :meth:`ForwardSolver.sensitivity`
  (dx/dC by the implicit function theorem).
* ``'lbfgs'`` (the default before Newton, and without cvxopt): L-BFGS whose initial inverse
  Hessian is the factorised global matrix, so its first step *is* a local/global iteration; an Armijo test on
  the energy keeps it monotone. Thin bending structures need several times fewer iterations.

Convergence: a linear-rate fixed-point map can take tiny steps far from its fixed point, so
the local/global solver stops when ``step / (1 - rho)`` (rho: observed contraction) is below
``tol`` (m); L-BFGS stops after three consecutive steps below ``tol``; Newton when an exact
Newton step is below ``tol`` (then the error is of second order). This is strict enough
for finite-difference IK gradients (a loose "tip moved < 1e-3 mm" stop can halt degrees short
after a warm start).

Cables are unilateral, handled by an active set: a slack cable's elements exert nothing
(their target is their current shape).
"""
from __future__ import annotations

import dataclasses
from typing import List, Optional

import numpy as np

from .global_step import GlobalSolver, assemble_system_matrix
from .local_step import (KIND_CODES, element_measure_ratios, local_targets,
                         local_step_numpy, rest_measures, scatter_rhs)
from .mesh import SoftMesh, element_measures, tet_volumes
from .newton import NewtonSystem, dgrad_dratio
from .newton import available as newton_available


@dataclasses.dataclass
class FKResult:
    """Result of one forward-kinematics solve.

    Attributes
    ----------
    positions : ndarray, shape (n_v, 3)
        Deformed vertex positions (m).
    actuation : ndarray, shape (n_a,)
        The actuation ratios solved for.
    iterations : int
        Local/global iterations taken.
    converged : bool
        Whether the error estimate fell below the tolerance.
    error_estimate : float
        Estimated distance (m) to the fixed point at the end.
    energy : ndarray, shape (iterations + 1,)
        Energy of eq. 9 at each accepted iterate (J-free units m^5: weight x m^3 x m^2).
    actuator_totals : ndarray, shape (n_a,)
        Achieved constraint totals divided by the required ones (1.0 = met exactly);
        NaN for slack cables.
    accepted_accelerations : int
        Anderson steps kept by the safeguard.
    levels : ndarray, shape (n_a,)
        Final actuation levels (uniform local ratios).
    active : ndarray of bool, shape (n_a,)
        Which actuators were taut (cables can be slack).
    """

    positions: np.ndarray
    actuation: np.ndarray
    iterations: int
    converged: bool
    error_estimate: float
    energy: np.ndarray
    actuator_totals: np.ndarray
    accepted_accelerations: int = 0
    levels: Optional[np.ndarray] = None
    active: Optional[np.ndarray] = None

    def marker(self, mesh: SoftMesh, name: str = 'tip') -> np.ndarray:
        """Position (m), shape (3,), of a named marker vertex."""
        return self.positions[mesh.markers[name]]


@dataclasses.dataclass
class _Group:
    elements: np.ndarray
    kind: int
    rest_centred: np.ndarray
    rest_volume: np.ndarray
    coef: np.ndarray
    shape_parameter: np.ndarray
    ratios: np.ndarray
    passive: np.ndarray
    targets: np.ndarray
    energy: np.ndarray


@dataclasses.dataclass
class _ActuatorData:
    group: int
    kind: str
    rest_measure: np.ndarray
    total_length: float
    bounds: tuple
    multiplicity: int


class ForwardSolver:
    """Forward kinematics of a :class:`SoftMesh` (Algorithm 1).

    Parameters
    ----------
    mesh : SoftMesh
        Rest shape, element groups, actuators and fixed vertices.
    backend : str
        Global-step factorisation back end (see :class:`GlobalSolver`).
    use_numba : bool
        False switches the local step to the plain numpy implementation (benchmark baseline).

    Attributes
    ----------
    reuse_memory : bool
        Seed each L-BFGS solve with the curvature pairs of the previous one (default True).

    Examples
    --------
    >>> from softkin_fk.core.models import build_tendon_finger
    >>> finger = build_tendon_finger(resolution=4)
    >>> solver = ForwardSolver(finger)
    >>> result = solver.solve([0.97, 1.0, 1.0])
    >>> result.converged
    True
    """

    def __init__(self, mesh: SoftMesh, backend: str = 'auto', use_numba: bool = True):
        self.mesh = mesh
        self.reuse_memory = True
        self._memory = ([], [])
        self._active = np.ones(len(mesh.actuators), bool)
        self.use_numba = use_numba
        self._newton = None
        self._last_factor = None
        #: local/global iterations after each trial Newton step (0: plain Newton)
        self.newton_correction = 1
        #: test convergence by a chord step with the previous factor (cheaper, but it can
        #: underestimate the distance where the Hessian changes fast along a soft mode)
        self.newton_chord = False
        #: a list to receive (iteration, step length, max |d|, energy, exact Hessian) per Newton step
        self.newton_log = None
        #: a cable at its rest length (s = 1) that a solve leaves slack but stretched beyond its
        #: length goes taut (its motor holds it). Off by default: s = 1 then stays slack, which
        #: admits paths up to ~3 % longer than the cable when proximal knuckles bend the finger.
        self.hold_rest_cables = False
        x0 = mesh.vertices
        self.groups: List[_Group] = []
        blocks = []
        for g in mesh.groups:
            kind = KIND_CODES[g.kind]
            w = float(g.weight)
            X = x0[g.elements]
            rc = np.ascontiguousarray(X - X.mean(axis=1, keepdims=True))
            meas = element_measures(x0, g)
            if np.any(meas <= 0):
                bad = int(np.argmin(meas))
                raise ValueError(f"element {bad} of group {g.name!r} is degenerate (measure {meas[bad]:.3g})")
            if g.k == 4:
                rvol = tet_volumes(x0, g.elements)
            else:
                rvol = meas.copy()
            coef = w * meas
            n = len(g.elements)
            self.groups.append(_Group(g.elements, kind, rc, rvol, coef, g.shape_parameter.copy(),
                                      np.ones(n), np.zeros(n, bool), np.zeros((n, g.k, 3)), np.zeros(n)))
            blocks.append((g.elements, coef))
        self.A = assemble_system_matrix(mesh.n_vertices, blocks)
        self.global_solver = GlobalSolver(self.A, mesh.fixed, backend=backend)
        names = [g.name for g in mesh.groups]
        self.actuators: List[_ActuatorData] = []
        for a in mesh.actuators:
            gi = names.index(a.group)
            g = mesh.groups[gi]
            rm = rest_measures(x0, g.elements, g.kind)
            mult = int(a.segment_multiplicity)
            if g.kind == 'cable' and a.total_length < rm.sum() / mult:
                raise ValueError(f"cable {a.name!r}: total length {a.total_length} m is shorter than its gap "
                                 f"segments ({rm.sum() / mult} m)")
            self.actuators.append(_ActuatorData(gi, g.kind, rm, float(a.total_length), tuple(a.bounds), mult))

    # --------------------------------------------------------------------------------------
    def constraint_total(self, a: int, value: float) -> float:
        """Required total of actuator ``a`` for ratio ``value`` (right side of eq. 6, 7 or 8)."""
        ad = self.actuators[a]
        m = ad.rest_measure.sum()
        if ad.kind == 'cable':
            # eq. 6: sum s_i l_i = s L - L_R with L_R = L - sum l_i (per copy of the cable)
            return m - (1.0 - value) * ad.total_length * ad.multiplicity
        return value * m  # lambda A or alpha U

    def initial_levels(self, actuation: np.ndarray) -> np.ndarray:
        """Starting actuation levels sigma (uniform local ratios) for an actuation vector."""
        lv = np.empty(len(self.actuators))
        for a, ad in enumerate(self.actuators):
            lv[a] = self.constraint_total(a, actuation[a]) / ad.rest_measure.sum()
        return lv

    def _totals(self, x: np.ndarray) -> np.ndarray:
        """Current sum_i c_i m_i per actuator (c_i current ratio, m_i rest measure)."""
        out = np.empty(len(self.actuators))
        for a, ad in enumerate(self.actuators):
            grp = self.groups[ad.group]
            cur = element_measure_ratios(x, grp.elements, grp.kind, ad.rest_measure)
            out[a] = float(cur @ ad.rest_measure)
        return out

    def _set_levels(self, levels: Optional[np.ndarray]) -> None:
        if levels is None:
            levels = np.ones(len(self.actuators))
        for a, ad in enumerate(self.actuators):
            grp = self.groups[ad.group]
            grp.ratios[:] = levels[a]
            grp.passive[:] = not self._active[a]

    def local_step(self, x: np.ndarray, levels: Optional[np.ndarray] = None) -> float:
        """Compute targets at ``x`` (in place) for actuation ``levels``; return the energy of
        eq. 9 at ``x``."""
        self._set_levels(levels)
        e = 0.0
        for grp in self.groups:
            if len(grp.elements) == 0:
                continue
            if self.use_numba:
                local_targets(x, grp.elements, grp.rest_centred, grp.kind, grp.ratios, grp.passive,
                              grp.shape_parameter, grp.rest_volume, grp.coef, grp.targets, grp.energy)
            else:
                grp.targets[:], grp.energy[:] = local_step_numpy(
                    x, grp.elements, grp.rest_centred, grp.kind, grp.ratios, grp.passive,
                    grp.shape_parameter, grp.rest_volume, grp.coef)
            e += float(grp.energy.sum())
        return e

    def global_step(self, fixed_positions: np.ndarray, out: Optional[np.ndarray] = None) -> np.ndarray:
        """Solve eq. 10 with the current targets; returns positions (n_v, 3)."""
        return self.global_solver.solve(self.rhs(), fixed_positions, out=out)

    def rhs(self) -> np.ndarray:
        """b = sum_i c_i S_i^T P_i for the current targets, shape (n_v, 3)."""
        rhs = np.zeros((self.mesh.n_vertices, 3))
        for grp in self.groups:
            if self.use_numba:
                scatter_rhs(grp.elements, grp.coef, grp.targets, rhs)
            else:
                np.add.at(rhs, grp.elements.ravel(), (grp.coef[:, None, None] * grp.targets).reshape(-1, 3))
        return rhs

    def actuator_totals(self, x: np.ndarray, actuation: np.ndarray, levels: Optional[np.ndarray] = None) -> np.ndarray:
        """Achieved / required constraint totals per actuator (NaN for slack cables)."""
        totals = self._totals(x)
        out = np.empty(len(self.actuators))
        for a, ad in enumerate(self.actuators):
            out[a] = totals[a] / self.constraint_total(a, actuation[a])
            if ad.kind == 'cable' and not self._active[a]:
                out[a] = np.nan
        return out

    # --------------------------------------------------------------------------------------
    def solve(self, actuation=None, x0: Optional[np.ndarray] = None, fixed_positions: Optional[np.ndarray] = None,
              tol: float = 1e-7, max_iter: int = 5000, min_iter: int = 2, accelerate: bool = True,
              window: int = 5, record_energy: bool = True, safeguard: str = 'auto',
              levels0: Optional[np.ndarray] = None, enforce_constraints: bool = False,
              constraint_tol: float = 1e-4, max_outer: int = 12, method: str = 'auto',
              active0: Optional[np.ndarray] = None) -> FKResult:
        """Deformed shape for an actuation vector (Algorithm 1).

        Parameters
        ----------
        actuation : array_like, shape (n_a,), optional
            Ratios (cable s, DEA lambda, pneumatic alpha); default all 1.0 (rest).
        x0 : ndarray, shape (n_v, 3), optional
            Initial shape (warm start); default the rest shape.
        fixed_positions : ndarray, shape (n_f, 3), optional
            Prescribed positions of the fixed vertices (handles); default their rest positions.
        tol : float
            Stop when the estimated distance to the fixed point is below ``tol`` (m).
        max_iter : int
            Iteration limit.
        min_iter : int
            Iterations always taken (the contraction estimate needs two steps).
        accelerate : bool
            Safeguarded Anderson acceleration.
        window : int
            Anderson history length.
        record_energy : bool
            Keep the energy of every accepted iterate.
        safeguard : {'auto', 'energy', 'residual', 'none'}
            Acceptance test of accelerated iterates: 'energy' keeps one only if the energy of
            eq. 9 does not increase (exact for fixed target shapes: R_w = 1 and no active
            actuator); 'residual' keeps it only if the fixed-point residual does not grow
            (for actuated / volume-blended problems, whose targets depend on the iterate);
            'auto' picks by that rule.
        levels0 : ndarray, shape (n_a,), optional
            Actuation levels (uniform local target ratios) to use instead of the nominal ones.
        enforce_constraints : bool
            Meet eq. 6-8 exactly: the actuation elements are penalty targets (weight 5.0), so
            a stiff body keeps them from reaching their nominal ratio; with this flag the
            levels are corrected by a secant iteration (each step a warm-started solve) until
            the relative constraint gap is below ``constraint_tol``.
        constraint_tol : float
            Tolerance on (required - achieved) / sum of rest measures.
        max_outer : int
            Limit on secant steps.
        method : {'auto', 'lbfgs', 'local-global'}
            'local-global' is Algorithm 1 as printed (optionally Anderson-accelerated);
            'lbfgs' minimises the same energy by L-BFGS whose initial inverse Hessian is the
            factorised global matrix (first step = one local/global iteration; every step
            passes an Armijo energy test). 'auto' takes L-BFGS when the energy is a true
            potential (all R_w = 1, so the soft blend of eq. 5 is off) and acceleration is
            on, else local/global.
        active0 : ndarray of bool, shape (n_a,), optional
            Initial active set of the unilateral cables (``FKResult.active`` of a previous
            solve); default: taut iff pulled (s < 1).

        Returns
        -------
        FKResult

        Raises
        ------
        ValueError
            On an actuation vector of the wrong length or outside the actuator bounds.
        """
        mesh = self.mesh
        na = len(self.actuators)
        act = np.ones(na) if actuation is None else np.asarray(actuation, float).ravel()
        if act.shape != (na,):
            raise ValueError(f"actuation has {act.size} values, expected {na} "
                             f"({[a.name for a in mesh.actuators]})")
        for a, ad in enumerate(self.actuators):
            lo, hi = ad.bounds
            if not (lo - 1e-12 <= act[a] <= hi + 1e-12) or not np.isfinite(act[a]):
                raise ValueError(f"actuation of {mesh.actuators[a].name!r} = {act[a]} is outside its "
                                 f"bounds [{lo}, {hi}]")
        x = mesh.vertices.copy() if x0 is None else np.array(x0, float)
        if x.shape != mesh.vertices.shape:
            raise ValueError(f"x0 has shape {x.shape}, expected {mesh.vertices.shape}")
        fixed = mesh.fixed
        fpos = mesh.vertices[fixed] if fixed_positions is None else np.asarray(fixed_positions, float)
        if fpos.shape != (len(fixed), 3):
            raise ValueError(f"fixed_positions has shape {fpos.shape}, expected ({len(fixed)}, 3)")
        x[fixed] = fpos
        if safeguard == 'auto':
            variational = all(np.all(g.shape_parameter == 1.0) for g in self.groups if g.kind == 0)
            safeguard = 'energy' if variational else 'residual'
        if method == 'auto':
            if safeguard == 'energy' and accelerate:
                method = 'newton' if newton_available() and self.use_numba else 'lbfgs'
            else:
                method = 'local-global'
        if method not in ('newton', 'lbfgs', 'local-global'):
            raise ValueError(f"method {method!r} is not 'auto', 'newton', 'lbfgs' or 'local-global'")
        if method == 'newton' and safeguard != 'energy':
            raise ValueError("method 'newton' minimises the energy of eq. 9, which needs all R_w = 1")
        if safeguard not in ('energy', 'residual', 'none'):
            raise ValueError(f"safeguard {safeguard!r} is not 'auto', 'energy', 'residual' or 'none'")

        levels = self.initial_levels(act) if levels0 is None else np.array(levels0, float)
        def inner(xs, lvs):
            if method == 'newton':
                return self._newton_solve(xs, lvs, fpos, tol, max_iter, min_iter, record_energy,
                                          warm=x0 is not None)
            if method == 'lbfgs':
                return self._lbfgs_solve(xs, lvs, fpos, tol, max_iter, min_iter, window, record_energy)
            return self._inner_solve(xs, lvs, fpos, tol, max_iter, min_iter, accelerate, window, safeguard,
                                     record_energy)

        # unilateral cables by an active set: a cable with s < 1 starts taut; after a solve a
        # taut cable that pushes (gap longer than its target: achieved total below the target
        # level) goes slack, a slack one that is over-stretched goes taut; then re-solve.
        sums = np.array([ad.rest_measure.sum() for ad in self.actuators])
        self._active = np.array([not (ad.kind == 'cable' and act[a] >= 1.0) for a, ad in enumerate(self.actuators)],
                                bool)
        if active0 is not None:
            self._active = np.asarray(active0, bool).copy()
        energies = np.zeros(0)
        it = n_acc = 0
        for _ in range(6):
            x, E, e1, i1, converged, est, n1 = inner(x, levels)
            energies = np.concatenate([energies, e1])
            it += i1
            n_acc += n1
            got = self._totals(x)
            changed = False
            for a, ad in enumerate(self.actuators):
                if ad.kind != 'cable':
                    continue
                stretched = got[a] > levels[a] * sums[a] * (1 + 1e-9)
                if self._active[a] and got[a] < levels[a] * sums[a] * (1 - 1e-6):
                    self._active[a] = False
                    changed = True
                elif not self._active[a] and stretched and (levels[a] < 1.0 or self.hold_rest_cables):
                    self._active[a] = True
                    changed = True
            if not changed:
                break
        outer = 0
        if enforce_constraints and self.actuators:
            # secant iteration on the levels so that eq. 6-8 hold exactly at the fixed point
            need = np.array([self.constraint_total(a, act[a]) for a in range(na)])
            prev = None
            for outer in range(1, max_outer + 1):
                got = self._totals(x)
                gap = (need - got) / sums
                active = self._active.copy()
                if np.all(np.abs(gap[active]) < constraint_tol):
                    break
                slope = np.ones(na)
                if prev is not None:
                    dl = levels - prev[0]
                    dg = (got - prev[1]) / sums
                    ok = np.abs(dl) > 1e-12
                    slope[ok] = np.clip(dg[ok] / dl[ok], 0.05, 2.0)
                prev = (levels.copy(), got)
                new = levels + np.where(active, gap / slope, 0.0)
                for a, ad in enumerate(self.actuators):
                    new[a] = min(max(new[a], 0.02), 1.0 if ad.kind == 'cable' else 50.0)
                levels = new
                x, E, e2, i2, converged, est, n2 = inner(x, levels)
                energies = np.concatenate([energies, e2])
                it += i2
                n_acc += n2
        lv = levels
        return FKResult(positions=x, actuation=act, iterations=it, converged=converged,
                        error_estimate=float(est), energy=np.asarray(energies),
                        actuator_totals=self.actuator_totals(x, act, lv), accepted_accelerations=n_acc,
                        levels=np.asarray(lv, float), active=self._active.copy())

    def _inner_solve(self, x, levels, fpos, tol, max_iter, min_iter, accelerate, window, safeguard,
                     record_energy):
        """Local/global iterations with fixed actuation levels (a proper energy minimisation
        for R_w = 1). Returns (x, E, energies, iterations, converged, error_estimate, n_acc)."""
        free = self.global_solver.free
        energies = []
        rho = 0.0
        est = np.inf
        converged = False
        prev_step = None
        it = 0
        dG, dF = [], []
        n_acc = 0
        fallback = None  # plain step behind the last accelerated iterate
        aa_last = None
        res_prev = np.inf
        E_prev = np.inf
        E = self.local_step(x, levels)
        for it in range(1, max_iter + 1):
            if it > 1:
                E = self.local_step(x, levels)
            reject = False
            if fallback is not None:
                if safeguard == 'energy':
                    reject = E > E_prev
                if reject:
                    x = fallback
                    E = self.local_step(x, levels)
                    dG.clear()
                    dF.clear()
                    aa_last = None
                    n_acc -= 1
            g = self.global_step(fpos)
            f = (g[free] - x[free]).ravel()
            if safeguard == 'residual' and fallback is not None and not reject:
                res = float(np.linalg.norm(f))
                if res > res_prev:
                    x = fallback
                    E = self.local_step(x, levels)
                    g = self.global_step(fpos)
                    f = (g[free] - x[free]).ravel()
                    dG.clear()
                    dF.clear()
                    aa_last = None
                    n_acc -= 1
            res_prev = float(np.linalg.norm(f))
            if record_energy:
                energies.append(E)
            E_prev = E
            fallback = None
            step_plain = float(np.max(np.abs(f))) if f.size else 0.0
            x_next = g
            if accelerate:
                gf = g[free].ravel()
                if aa_last is not None:
                    dG.append(gf - aa_last[0])
                    dF.append(f - aa_last[1])
                    if len(dG) > window:
                        dG.pop(0)
                        dF.pop(0)
                aa_last = (gf, f)
                if dF:
                    gamma, *_ = np.linalg.lstsq(np.column_stack(dF), f, rcond=1e-10)
                    xa = gf - np.column_stack(dG) @ gamma
                    if np.all(np.isfinite(xa)):
                        x_next = g.copy()
                        x_next[free] = xa.reshape(-1, 3)
                        fallback = g
                        n_acc += 1
            if prev_step is not None and prev_step > 0:
                rho = max(0.5 * rho, min(step_plain / prev_step, 0.999))
            prev_step = step_plain
            est = step_plain / (1.0 - rho)
            x = x_next
            if it >= min_iter and est < tol:
                converged = True
                x = g  # end on a plain (unaccelerated) iterate
                break
        E = self.local_step(x, levels)
        if fallback is not None and not converged and safeguard == 'energy' and E > E_prev:
            x = fallback  # the loop ended on an accelerated iterate that the safeguard rejects
            E = self.local_step(x, levels)
        if record_energy:
            energies.append(E)
        return x, E, np.asarray(energies), it, converged, est, n_acc

    def _lbfgs_solve(self, x, levels, fpos, tol, max_iter, min_iter, history, record_energy):
        """Minimise eq. 9 with fixed actuation levels by L-BFGS preconditioned with the
        factorised global matrix (its first step is exactly one local/global iteration;
        Liu, Bouaziz & Kavan 2017). Every step passes an Armijo test on the energy, so the
        energy never increases. Returns like :meth:`_inner_solve`."""
        gs = self.global_solver
        free = gs.free
        x = x.copy()
        E = self.local_step(x, levels)
        grad = gs.residual(x, self.rhs())          # half gradient, (n_free, 3)
        energies = [E] if record_energy else []
        # curvature pairs of the previous solve (same mesh, nearby state) seed the quasi-Newton
        # model: consecutive warm-started solves (IK differences, trajectories) then need far
        # fewer iterations
        S, Y = self._memory if self.reuse_memory else ([], [])
        S, Y = list(S), list(Y)
        small = 0
        converged = False
        it = 0
        step_norm = np.inf
        for it in range(1, max_iter + 1):
            # two-loop recursion with H0 = A_ff^{-1}
            q = grad.ravel().copy()
            alphas = []
            for s_, y_ in zip(reversed(S), reversed(Y)):
                rho_ = 1.0 / float(y_ @ s_)
                a_ = rho_ * float(s_ @ q)
                alphas.append((a_, rho_, s_, y_))
                q -= a_ * y_
            r = gs.solve_free(q.reshape(-1, 3)).ravel()
            for a_, rho_, s_, y_ in reversed(alphas):
                b_ = rho_ * float(y_ @ r)
                r += (a_ - b_) * s_
            d = -r
            slope = 2.0 * float(grad.ravel() @ d)
            if not slope < 0:
                S.clear()
                Y.clear()
                d = -gs.solve_free(grad).ravel()
                slope = 2.0 * float(grad.ravel() @ d)
            step = 1.0
            x_old_free = x[free].copy()
            for _ in range(30):
                x[free] = x_old_free + step * d.reshape(-1, 3)
                E_new = self.local_step(x, levels)
                if E_new <= E + 1e-4 * step * slope:
                    break
                step *= 0.5
            else:
                # no descent along d (round-off level): stop; converged if the last step was tiny
                x[free] = x_old_free
                E_new = self.local_step(x, levels)
                step_norm = float(np.max(np.abs(gs.solve_free(grad)))) if grad.size else 0.0
                converged = step_norm < tol  # the plain local/global step is negligible too
                break
            grad_new = gs.residual(x, self.rhs())
            s_vec = (x[free] - x_old_free).ravel()
            y_vec = 2.0 * (grad_new - grad).ravel()
            if float(y_vec @ s_vec) > 1e-12 * float(np.linalg.norm(y_vec) * np.linalg.norm(s_vec)):
                S.append(s_vec)
                Y.append(y_vec)
                if len(S) > history:
                    S.pop(0)
                    Y.pop(0)
            E, grad = E_new, grad_new
            if record_energy:
                energies.append(E)
            step_norm = float(np.max(np.abs(s_vec))) if s_vec.size else 0.0
            small = small + 1 if step_norm < tol else 0
            if it >= max(min_iter, 10) and small >= 3:
                converged = True
                break
        self._memory = (S, Y)
        return x, E, np.asarray(energies), it, converged, step_norm, 0

    # --------------------------------------------------------------------------------------
    def newton_system(self) -> NewtonSystem:
        """The Hessian pattern and symbolic factorisation (built on first use)."""
        if self._newton is None:
            h = float(np.median([np.cbrt(np.median(g.rest_volume[g.rest_volume > 0]))
                                 for g in self.groups if g.kind == 0 and len(g.elements)]))
            self._newton = NewtonSystem(self.groups, self.mesh.n_vertices, self.global_solver.free, h)
        return self._newton

    def _newton_factor(self, ns: NewtonSystem, H: np.ndarray, shifts: int = 8):
        """Cholesky of an assembled Hessian; a growing diagonal shift if round-off makes the
        (projected, PSD) matrix indefinite. Raises ArithmeticError after ``shifts`` tries."""
        shift = 0.0
        diag = ns.diagonal
        for k in range(shifts + 1):
            try:
                if shift == 0.0:
                    return ns.factor(H)
                Hs = H.copy()
                Hs[diag] += shift
                return ns.factor(Hs)
            except ArithmeticError:
                ns.reset()
                if k == shifts:
                    raise
                shift = 1e-10 * float(np.mean(H[diag])) if shift == 0.0 else 100.0 * shift
        raise ArithmeticError("Newton Hessian could not be factorised")

    def _newton_solve(self, x, levels, fpos, tol, max_iter, min_iter, record_energy, warm=False):
        """Newton on eq. 9 with fixed actuation levels (all R_w = 1), globalised by an Armijo
        backtracking line search on the energy (so the energy never increases).

        Hessian: from rest and after a damped step each element Hessian is projected onto PSD
        (exactly, in its 3-dim rotation subspace, see :mod:`.newton`) so the direction
        descends; from a warm start and after a full step the exact Hessian is tried first
        (compressed elements are indefinite on their own, but the assembled Hessian is
        positive definite near a strict minimiser), which restores quadratic convergence; if
        its Cholesky fails or its direction does not descend, the projected one is used.

        Each trial point x + alpha d of a step longer than a tenth of an element is followed
        by ``newton_correction`` local/global iterations (cheap: back-substitutions with the
        factor of eq. 10) before the energy test: a linear step along a large rotation
        stretches elements, and one local/global iteration re-fits the rotations; on the
        240-degree bender this halves the Newton iterations. If no corrected trial passes, the
        plain line search is used.

        Converged when a Newton step with the exact Hessian moves no coordinate by more than
        ``tol`` (m): the remaining error is then of second order (a step by a projected
        Hessian is no proof: it is stiffer than the true one along soft modes). On a saddle
        (exact Hessian indefinite) projected steps are all there is and count. The loop also
        stops when the energy stagnates at round-off.
        Returns like :meth:`_inner_solve`."""
        ns = self.newton_system()
        self._set_levels(levels)
        free = ns.free
        x = x.copy()
        x[self.global_solver.fixed] = fpos
        exact = warm  # a warm start is usually close: try the exact Hessian first
        E, g, H = ns.evaluate(x, project=0 if exact else 1)
        energies = [E] if record_energy else []
        converged = False
        step_norm = np.inf
        it = 0
        chord = None      # direction from the previous factor at the current x (cheap convergence test)
        x_H = x           # where the current factor's Hessian was assembled
        # a local/global correction pays only for steps that are not small against an element
        corr_min = 0.1 * ns.scale
        stalled = 0
        while it < max_iter:
            it += 1
            if chord is not None:
                d, chord = chord, None
                if not (float(np.max(np.abs(d))) < tol and it >= min_iter and exact):
                    # not converged yet: a fresh (exact) Newton step from here
                    E, g, H = ns.evaluate(x, project=0)
                    exact = True
                    d = None
            else:
                d = None
            exact_failed = False
            if d is None:
                F = None
                if exact:
                    try:
                        F = self._newton_factor(ns, H, shifts=0)
                        d = -ns.solve(F, g)
                        if not float(g @ d) < 0:
                            F = None
                    except ArithmeticError:
                        F = None
                    if F is None:
                        exact = False
                        exact_failed = True
                        E, g, H = ns.evaluate(x, project=1)
                if F is None:
                    F = self._newton_factor(ns, H)
                    d = -ns.solve(F, g)
                x_H = x
                F_exact = exact
            step_norm = float(np.max(np.abs(d))) if d.size else 0.0
            slope = float(g @ d)
            x_old = x.copy()
            if step_norm < tol and it >= min_iter and not exact and not exact_failed:
                # a projected Hessian is stiffer than the true one in soft directions, so a small
                # projected step does not prove convergence: test with the exact Hessian
                E, g, H = ns.evaluate(x, project=0)
                exact = True
                continue
            if step_norm < tol and it >= min_iter:
                # at the minimiser within tol: take the plain step unless round-off makes E rise
                x[free] += d.reshape(-1, 3)
                E_new, g_new, _ = ns.evaluate(x, hessian=False)
                if E_new <= E:
                    E, g = E_new, g_new
                else:
                    x = x_old
                if record_energy:
                    energies.append(E)
                converged = True
                # the factor is the exact Hessian at x_H (within a step of the result): reusable
                # by sensitivity() without refactorising when x_H is close enough
                self._last_factor = (ns.version, exact, x, levels.copy(), self._active.copy(),
                                     float(np.max(np.abs(x - x_H))))
                break
            accepted = False
            H_new = None
            # after a full step the next iteration (or the convergence test) needs the exact
            # Hessian there anyway: assemble it with the energy test
            fused = not self.newton_chord or step_norm > 100.0 * tol
            for corr in ((self.newton_correction, 0) if self.newton_correction and step_norm > corr_min else (0,)):
                alpha = 1.0
                for _ in range(40):
                    x = x_old.copy()
                    x[free] += alpha * d.reshape(-1, 3)
                    for _ in range(corr):
                        self.local_step(x, levels)
                        x = self.global_step(fpos, out=x)
                    # the full step is usually accepted: assemble the next (exact) Hessian with
                    # the energy test instead of a second pass
                    E_new, g_new, H_new = ns.evaluate(x, hessian=fused and alpha == 1.0, project=0)
                    # Armijo; at round-off level (tiny steps) accept what does not increase E
                    if E_new <= E + 1e-4 * alpha * slope or (alpha * step_norm < tol and E_new <= E):
                        accepted = True
                        break
                    alpha *= 0.5
                if accepted:
                    break
            if not accepted:
                x = x_old  # no decrease along d: round-off level, stop here
                converged = step_norm < tol
                break
            # stagnation at round-off (tol below what double precision resolves): stop
            stalled = stalled + 1 if E_new >= E * (1.0 - 1e-14) else 0
            if record_energy:
                energies.append(E_new)
            if stalled >= 5:
                E, g = E_new, g_new
                break
            if self.newton_log is not None:
                self.newton_log.append((it, alpha, step_norm, E_new, exact))
            exact = alpha == 1.0
            if exact and H_new is not None:
                E, g, H = E_new, g_new, H_new
            elif exact and self.newton_chord:
                # small full step: test convergence with the previous factor (a chord step,
                # one back-substitution) before assembling and factorising again; only an
                # exact factor is a valid test (``exact`` stays that of the factor)
                E, g = E_new, g_new
                exact = F_exact
                chord = -ns.solve(F, g)
            elif exact:
                E, g, H = ns.evaluate(x, project=0)
            else:
                E, g, H = ns.evaluate(x, project=1)
        return x, E, np.asarray(energies), it, converged, step_norm, 0

    def newton_applicable(self) -> bool:
        """Whether the Newton solver (and :meth:`sensitivity`) applies: eq. 9 is a true energy
        (all body R_w = 1), the sparse Cholesky back end is installed, and the numba kernels
        are in use (``use_numba=False`` is the plain-numpy baseline: local/global, L-BFGS)."""
        return (newton_available() and self.use_numba
                and all(np.all(g.shape_parameter == 1.0) for g in self.groups if g.kind == 0))

    def level_derivatives(self) -> np.ndarray:
        """d sigma_a / d C_a: how the actuation level (uniform local ratio) of each actuator
        changes with its actuation ratio (eq. 6: L m_c / sum l_i for cables; 1 otherwise)."""
        out = np.ones(len(self.actuators))
        for a, ad in enumerate(self.actuators):
            if ad.kind == 'cable':
                out[a] = ad.total_length * ad.multiplicity / ad.rest_measure.sum()
        return out

    def sensitivity(self, result: FKResult, reuse_tol: float = 1e-6, one_sided: bool = True) -> np.ndarray:
        """Derivative of the deformed shape with respect to the actuation, dx/dC, by the
        implicit function theorem: at a minimiser grad E(x, sigma) = 0, so
        dx/dsigma = -H^{-1} d(grad E)/dsigma with the exact Hessian H of eq. 9 (:mod:`.newton`).

        A slack cable whose gap is at (or beyond) its target length would tighten as soon as it
        is pulled: its column is the one-sided derivative in the pulling direction, with that
        cable taut and the others as they are (as a one-sided difference at s = 1); a cable
        slack with room to spare gets zero.

        Parameters
        ----------
        result : FKResult
            A converged solve with the nominal levels (``enforce_constraints=False``) of a
            problem with all R_w = 1.
        reuse_tol : float
            The Newton solve's last factorisation is reused when its Hessian was assembled
            within this distance (m) of the result (else a fresh one is made; a predictor can
            afford a large value, an IK Jacobian wants a small one).
        one_sided : bool
            Give marginal slack cables their pulling derivative (a Hessian per such column);
            False keeps every actuator as the solve left it (slack columns are zero), so the
            solve's last factorisation serves all columns (enough for a predictor).

        Returns
        -------
        ndarray, shape (n_v, 3, n_a)
            dx/dC (m per unit actuation ratio); fixed vertices have zero rows.
        """
        ns = self.newton_system()
        x = result.positions
        levels = np.asarray(result.levels, float)
        base_active = np.asarray(result.active, bool)
        got = self._totals(x)
        na = len(self.actuators)
        # column a is taken with actuator a taut if it is, or would tighten when pulled
        # (a marginal slack cable); the other actuators keep their state
        col_active = []
        for a, ad in enumerate(self.actuators):
            act_a = base_active.copy()
            if one_sided and ad.kind == 'cable' and not act_a[a]:
                act_a[a] = got[a] >= levels[a] * ad.rest_measure.sum() * (1 - 1e-9)
            col_active.append(act_a)
        dl = self.level_derivatives()
        dx = np.zeros((self.mesh.n_vertices, 3, na))
        saved = self._active.copy()
        try:
            for key in {tuple(v) for v in col_active}:
                cols = [a for a in range(na) if tuple(col_active[a]) == key and col_active[a][a]]
                if not cols:
                    continue
                act_s = np.array(key, bool)
                self._active = act_s
                self._set_levels(levels)
                F = self._sensitivity_factor(ns, x, levels, act_s, reuse_tol)
                rhs = np.zeros((len(ns.free) * 3, len(cols)))
                for j, a in enumerate(cols):
                    grp = self.groups[self.actuators[a].group]
                    out = np.zeros((self.mesh.n_vertices, 3))
                    dgrad_dratio(x, grp.elements, grp.rest_centred, grp.kind, grp.ratios, grp.coef, ns.scale, out)
                    rhs[:, j] = out[ns.free].ravel() * dl[a]
                sol = -ns.solve(F, rhs).reshape(len(ns.free), 3, len(cols))
                for j, a in enumerate(cols):
                    dx[ns.free, :, a] = sol[:, :, j]
        finally:
            self._active = saved
        return dx

    def _sensitivity_factor(self, ns, x, levels, act_s, reuse_tol):
        """Factor of the exact Hessian at ``x`` (reusing the last Newton factorisation when it
        is exact, for this state, and assembled within ``reuse_tol`` of ``x``)."""
        lf = self._last_factor
        if (lf is not None and lf[0] == ns.version and lf[1] and lf[2] is x and lf[5] <= reuse_tol
                and np.array_equal(lf[3], levels) and np.array_equal(lf[4], act_s)):
            return ns._symbolic
        _, _, H = ns.evaluate(x, project=0)
        try:
            return self._newton_factor(ns, H, shifts=0)
        except ArithmeticError:  # not a strict minimiser: the projected Hessian
            _, _, H = ns.evaluate(x, project=1)
            return self._newton_factor(ns, H)

    def marker_position(self, actuation, name: str = 'tip', **kw) -> np.ndarray:
        """Convenience: solve and return one marker's position (m), shape (3,)."""
        return self.solve(actuation, **kw).marker(self.mesh, name)
