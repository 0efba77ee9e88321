"""Linear damping lumped on the rigid-body degrees of freedom (surge, sway, yaw).

The per-edge quadratic drag of eq. 1-2 is the only fluid force of the paper. A body
floating at the free surface also loses energy in ways that a planar quadratic drag
does not hold, each linear in velocity at these speeds:

* **radiation (wave-making) damping**: a body moving at the surface radiates waves that
  carry energy away; at low frequency and speed the force is linear in velocity
  (Newman, *Marine Hydrodynamics*, 1977, sec. 6.16);
* the **meniscus and contact line** along the waterline, whose hysteresis resists slow
  motion nearly linearly;
* the limbs' **recovery stroke** and rotational drag at their lever arm, averaged over
  a stroke.

Lumped on the rigid body as in marine manoeuvring models (Fossen, *Handbook of Marine
Craft Hydrodynamics and Motion Control*, 2011, eq. 6.64: ``D(nu) = D_L + D_NL(nu)``),
here only the linear part ``D_L = diag(X_u, Y_v, N_r)``: the quadratic part is the DER
drag itself. In the body frame (surge u forward, sway w left, yaw rate r)::

    F_u = -X_u u,   F_w = -Y_v w,   N = -N_r r

where u, w come from the COM velocity ``V = sum m_i v_i / M`` (eq. 10) and r from the
angular momentum about the COM, ``r = sum m_i (r_i x v_i) / I``, ``I = sum m_i |r_i|^2``.
The force and torque are spread over the nodes by mass, ``f_i = m_i F / M + m_i N
perp(r_i) / I``, which gives exactly F and N in total and dissipates exactly
``X_u u^2 + Y_v w^2 + N_r r^2`` (tested). The masses are the revised masses of eq. 4.

The term enters the integrator explicitly (evaluated at the start of each step, IMEX
Euler): it is linear and its rates ``N_r / I`` and ``X_u / M`` (0.37 and 0.15 1/s for the
calibrated frog) times dt (2 ms) are ~1e-3, far inside the explicit stability bound of 2;
and it couples every node, which an implicit treatment would add as a dense block to the
sparse Jacobian.
"""
from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import njit

from .element_sets import register_explicit_term
from .lumped_wrench import rigid_motion, spread_wrench


@njit(cache=True, error_model='numpy')
def body_damping_force(x, v, mass, reference, surge, sway, yaw, out):
    """Nodal forces (2N,) [N] of the lumped linear damping into ``out``; returns the power [W].

    Parameters
    ----------
    x, v : ndarray, shape (2N,)
        Positions [m] and velocities [m/s] (x0, y0, x1, ...).
    mass : ndarray, shape (N,)
        Nodal masses [kg] (eq. 4).
    reference : ndarray, shape (N, 2)
        Reference pose centred at its COM [m]: the body axes (heading by eq. 11, resolved
        as in :mod:`~frog_sim.core.rigid_body`); unused when ``surge == sway``.
    surge, sway : float
        X_u, Y_v [N s/m].
    yaw : float
        N_r [N m s/rad].
    """
    mt, cx, cy, vx, vy, inertia, r = rigid_motion(x, v, mass)
    if surge == sway:
        fx = -surge * vx
        fy = -surge * vy
    else:
        cross = 0.0
        dot = 0.0
        for i in range(mass.shape[0]):
            rx = x[2 * i] - cx
            ry = x[2 * i + 1] - cy
            cross += mass[i] * (reference[i, 0] * ry - reference[i, 1] * rx)
            dot += mass[i] * (reference[i, 0] * rx + reference[i, 1] * ry)
        th = np.arctan2(cross, dot)
        c = np.cos(th)
        s = np.sin(th)
        fu = -surge * (c * vx + s * vy)
        fw = -sway * (-s * vx + c * vy)
        fx = c * fu - s * fw
        fy = s * fu + c * fw
    torque = -yaw * r
    spread_wrench(x, mass, mt, cx, cy, inertia, fx, fy, torque, out)
    return fx * vx + fy * vy + torque * r


def body_damping(x, v, mass, reference, surge=0.0, sway=0.0, yaw=0.0) -> tuple[np.ndarray, float]:
    """:func:`body_damping_force` as a function: (forces (2N,) [N], power [W])."""
    out = np.zeros(np.asarray(x).size)
    power = body_damping_force(np.ascontiguousarray(x, dtype=float), np.ascontiguousarray(v, dtype=float),
                               np.ascontiguousarray(mass, dtype=float), np.ascontiguousarray(reference, dtype=float),
                               float(surge), float(sway), float(yaw), out)
    return out, float(power)


BodyDampingTerm = namedtuple('BodyDampingTerm', 'mass reference coefficients')
BodyDampingTerm.__doc__ = """The lumped body damping as an explicit integrator term. Its one element
touches every DOF (DOF map ``arange(2N)``): nodal masses (N,) [kg], the reference pose
(N, 2) [m] and (X_u, Y_v, N_r) (3,); all-zero coefficients switch it off."""


@njit(cache=True, inline='always', error_model='numpy')
def body_damping_term(term, m, xe, ve, force):
    """Explicit-term kernel of :class:`BodyDampingTerm`: the force at the start of the step."""
    c = term.coefficients
    if c[0] == 0.0 and c[1] == 0.0 and c[2] == 0.0:
        return False
    body_damping_force(xe, ve, term.mass, term.reference, c[0], c[1], c[2], force)
    return True


register_explicit_term(BodyDampingTerm, body_damping_term)
