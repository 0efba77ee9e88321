"""A straightforward numpy/scipy.sparse implementation of the same backward-Euler step.

This is the baseline of the benchmark (``bench/frog_sim_realtime.py``): vectorised
numpy for the element forces and Hessians, a COO -> CSR Jacobian built every Newton
iteration and ``scipy.sparse.linalg.spsolve`` (SuperLU), full Newton. Same equations
(paper eq. 1-8), same tolerances, same actuation as
:class:`~frog_sim.core.integrator.ImplicitEulerIntegrator`; a test checks that both
produce the same step.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .actuation import apply_actuation
from .fluid import drag_prefactors

_BMAT = np.zeros((4, 6))                     # u = (e1, e2) = B x_local
_BMAT[0:2, 0:2] = -np.eye(2)
_BMAT[0:2, 2:4] = np.eye(2)
_BMAT[2:4, 2:4] = -np.eye(2)
_BMAT[2:4, 4:6] = np.eye(2)
_D2C = np.zeros((4, 4))
_D2C[0, 3] = _D2C[3, 0] = 1.0
_D2C[1, 2] = _D2C[2, 1] = -1.0


class NumpyReferenceStepper:
    """Backward Euler + full Newton in plain numpy/scipy (slow reference).

    Parameters
    ----------
    network, mass, fluid_density, actuator, force_tolerance, position_tolerance, max_iterations
        As :class:`~frog_sim.core.integrator.ImplicitEulerIntegrator`.
    body_damping, reference, waterline_friction
        As there: the lumped linear damping and the waterline friction, held over each step
        from its start (written again here in vectorised numpy as an independent check of
        the numba kernels).
    """

    def __init__(self, network, mass, *, fluid_density=1000.0, actuator=None,
                 force_tolerance=1e-8, position_tolerance=1e-11, max_iterations=25,
                 body_damping=(0.0, 0.0, 0.0), reference=None, waterline_friction=(0.0, 0.0)):
        self.net = network
        self.waterline_friction = tuple(float(c) for c in waterline_friction)
        self.mass = np.asarray(mass, dtype=float)
        self.body_damping = tuple(float(c) for c in body_damping)
        pos = network.positions.astype(float)
        self.reference = (pos - self.mass @ pos / self.mass.sum()) if reference is None else np.asarray(reference)
        self.mass2 = np.repeat(np.asarray(mass, dtype=float), 2)
        self.cn, self.ct = drag_prefactors(network, fluid_density)
        self.actuator = actuator
        self.force_tolerance = force_tolerance
        self.position_tolerance = position_tolerance
        self.max_iterations = max_iterations
        self.kappa0 = network.bend_natural_curvature.copy()
        self.ei = network.bend_stiffness.copy()
        self.ea = network.edge_stretching_stiffness.copy()
        self.x = network.positions.ravel().astype(float).copy()
        self.v = np.zeros_like(self.x)
        self.time = 0.0
        n = network.n_dof
        self.n = n
        e, b = network.edges, network.bends
        self.edof = np.stack([2 * e[:, 0], 2 * e[:, 0] + 1, 2 * e[:, 1], 2 * e[:, 1] + 1], axis=1)
        self.bdof = np.stack([2 * b[:, 0], 2 * b[:, 0] + 1, 2 * b[:, 1], 2 * b[:, 1] + 1,
                              2 * b[:, 2], 2 * b[:, 2] + 1], axis=1)
        self.newton_iterations = 0

    # ------------------------------------------------------------------ physics
    def _stretch(self, x):
        xa = x[self.edof[:, 0:2]]
        xb = x[self.edof[:, 2:4]]
        e = xb - xa
        length = np.linalg.norm(e, axis=1)
        t = e / length[:, None]
        l0 = self.net.edge_rest_length
        eps = length / l0 - 1.0
        g = (self.ea * eps)[:, None] * t
        grad = np.concatenate([-g, g], axis=1)
        tt = t[:, :, None] * t[:, None, :]
        k = (self.ea / l0)[:, None, None] * tt + (self.ea * eps / length)[:, None, None] * (np.eye(2) - tt)
        hess = np.concatenate([np.concatenate([k, -k], axis=2), np.concatenate([-k, k], axis=2)], axis=1)
        return grad, hess

    def _bend(self, x):
        xl = x[self.bdof]
        u = xl @ _BMAT.T                                   # (B, 4)
        e1, e2 = u[:, 0:2], u[:, 2:4]
        n1 = np.linalg.norm(e1, axis=1)
        n2 = np.linalg.norm(e2, axis=1)
        c = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
        dd = n1 * n2 + np.sum(e1 * e2, axis=1)
        dl = self.net.bend_length
        kappa = 2 * c / (dd * dl)
        diff = kappa - self.kappa0
        dc = np.stack([e2[:, 1], -e2[:, 0], -e1[:, 1], e1[:, 0]], axis=1)
        t1 = e1 / n1[:, None]
        t2 = e2 / n2[:, None]
        dD = np.concatenate([n2[:, None] * t1 + e2, n1[:, None] * t2 + e1], axis=1)
        eye = np.eye(2)
        p1 = eye - t1[:, :, None] * t1[:, None, :]
        p2 = eye - t2[:, :, None] * t2[:, None, :]
        cross = t1[:, :, None] * t2[:, None, :] + eye
        d2D = np.concatenate([np.concatenate([(n2 / n1)[:, None, None] * p1, cross], axis=2),
                              np.concatenate([cross.transpose(0, 2, 1), (n1 / n2)[:, None, None] * p2],
                                             axis=2)], axis=1)
        s = (2.0 / dl)[:, None]
        inv = 1.0 / dd
        dk = s * (dc * inv[:, None] - (c * inv ** 2)[:, None] * dD)
        outer = lambda a, b: a[:, :, None] * b[:, None, :]  # noqa: E731
        d2k = (2.0 / dl)[:, None, None] * (
            _D2C[None] * inv[:, None, None]
            - (outer(dc, dD) + outer(dD, dc)) * (inv ** 2)[:, None, None]
            + 2.0 * (c * inv ** 3)[:, None, None] * outer(dD, dD)
            - (c * inv ** 2)[:, None, None] * d2D)
        w = self.ei * dl
        gu = (w * diff)[:, None] * dk
        hu = w[:, None, None] * (outer(dk, dk) + diff[:, None, None] * d2k)
        grad = gu @ _BMAT
        hess = np.einsum('ip,bij,jq->bpq', _BMAT, hu, _BMAT)
        return grad, hess

    def _drag(self, x, v):
        xa, xb = x[self.edof[:, 0:2]], x[self.edof[:, 2:4]]
        va, vb = v[self.edof[:, 0:2]], v[self.edof[:, 2:4]]
        e = xb - xa
        length = np.linalg.norm(e, axis=1)
        t = e / length[:, None]
        vm = 0.5 * (va + vb)
        speed = np.linalg.norm(vm, axis=1)
        vt = np.sum(t * vm, axis=1)
        cn, dc = self.cn, self.ct - self.cn
        f = -speed[:, None] * (cn[:, None] * vm + (dc * vt)[:, None] * t)
        force = 0.5 * np.concatenate([f, f], axis=1)
        inv_speed = np.where(speed > 1e-300, 1.0 / np.maximum(speed, 1e-300), 0.0)
        outer = lambda a, b: a[:, :, None] * b[:, None, :]  # noqa: E731
        eye = np.eye(2)
        g = -(cn[:, None, None] * (speed[:, None, None] * eye + outer(vm, vm) * inv_speed[:, None, None])
              + dc[:, None, None] * (speed[:, None, None] * outer(t, t)
                                     + outer(t, vm) * (vt * inv_speed)[:, None, None]))
        a = vt[:, None, None] * eye + outer(t, vm)
        pm = eye - outer(t, t)
        ge = (-speed * dc / length)[:, None, None] * (a @ pm)
        jv = 0.25 * np.concatenate([np.concatenate([g, g], axis=2)] * 2, axis=1)
        jx = 0.5 * np.concatenate([np.concatenate([-ge, ge], axis=2)] * 2, axis=1)
        return force, jv, jx

    def _body_damping(self, x, v):
        """-D_L nu of the rigid body spread over the nodes by mass (core/body_damping.py)."""
        xu, yv, nr = self.body_damping
        m = self.mass
        p, u = x.reshape(-1, 2), v.reshape(-1, 2)
        c, vc = m @ p / m.sum(), m @ u / m.sum()
        rel, vrel = p - c, u - vc
        inertia = m @ np.sum(rel ** 2, axis=1)
        r = m @ (rel[:, 0] * vrel[:, 1] - rel[:, 1] * vrel[:, 0]) / inertia
        ref = self.reference
        th = np.arctan2(m @ (ref[:, 0] * rel[:, 1] - ref[:, 1] * rel[:, 0]), m @ np.sum(ref * rel, axis=1))
        rot = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
        force = rot @ (np.array([-xu, -yv]) * (rot.T @ vc))
        perp = np.column_stack([-rel[:, 1], rel[:, 0]])
        return (m[:, None] * force / m.sum() + (m * (-nr * r) / inertia)[:, None] * perp).ravel()

    def _waterline_friction(self, x, v):
        """Coulomb friction (F_c, N_c) against the rigid body's V and r, regularised (core/waterline_friction.py)."""
        from .waterline_friction import SPEED_SCALE, YAW_RATE_SCALE
        fc, nc = self.waterline_friction
        m = self.mass
        p, u = x.reshape(-1, 2), v.reshape(-1, 2)
        c, vc = m @ p / m.sum(), m @ u / m.sum()
        rel, vrel = p - c, u - vc
        inertia = m @ np.sum(rel ** 2, axis=1)
        r = m @ (rel[:, 0] * vrel[:, 1] - rel[:, 1] * vrel[:, 0]) / inertia
        speed = float(np.hypot(*vc))
        force = -fc * (np.tanh(speed / SPEED_SCALE) / speed if speed > 0 else 1.0 / SPEED_SCALE) * vc
        torque = -nc * np.tanh(r / YAW_RATE_SCALE)
        perp = np.column_stack([-rel[:, 1], rel[:, 0]])
        return (m[:, None] * force / m.sum() + (m * torque / inertia)[:, None] * perp).ravel()

    def _system(self, x, x_prev, v_prev, h):
        v = (x - x_prev) / h
        gs, hs = self._stretch(x)
        gb, hb = self._bend(x)
        fd, jv, jx = self._drag(x, v)
        resid = self.mass2 * (x - x_prev - h * v_prev) / h ** 2
        if any(self.body_damping):
            resid -= self._body_damping(x_prev, v_prev)
        if any(self.waterline_friction):
            resid -= self._waterline_friction(x_prev, v_prev)
        resid += np.bincount(self.edof.ravel(), (gs - fd).ravel(), minlength=self.n)
        resid += np.bincount(self.bdof.ravel(), gb.ravel(), minlength=self.n)
        he = hs - jx - jv / h
        rows = np.concatenate([np.repeat(self.edof, 4, axis=1).ravel(),
                               np.repeat(self.bdof, 6, axis=1).ravel(), np.arange(self.n)])
        cols = np.concatenate([np.tile(self.edof, (1, 4)).ravel(), np.tile(self.bdof, (1, 6)).ravel(),
                               np.arange(self.n)])
        vals = np.concatenate([he.ravel(), hb.ravel(), self.mass2 / h ** 2])
        jac = sp.coo_matrix((vals, (rows, cols)), shape=(self.n, self.n)).tocsr()
        return resid, jac

    # ------------------------------------------------------------------ stepping
    def step(self, h: float) -> int:
        """One backward-Euler step; returns the Newton iterations (raises if unconverged)."""
        t_new = self.time + h
        if self.actuator is not None:
            apply_actuation(t_new, *self.actuator.as_tuple(), self.kappa0, self.ei, self.ea)
        x_prev, v_prev = self.x.copy(), self.v.copy()
        x = x_prev + h * v_prev
        for it in range(self.max_iterations):
            resid, jac = self._system(x, x_prev, v_prev, h)
            if np.max(np.abs(resid)) <= self.force_tolerance:
                break
            dx = spla.spsolve(jac.tocsc(), resid)
            x -= dx
            if np.max(np.abs(dx)) <= self.position_tolerance:
                it += 1
                break
        else:
            raise RuntimeError(f'numpy reference step did not converge at t = {self.time:.4g} s')
        self.newton_iterations += it
        self.x = x
        self.v = (x - x_prev) / h
        self.time = t_new
        return it
