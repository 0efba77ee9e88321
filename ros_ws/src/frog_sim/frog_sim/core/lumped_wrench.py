"""A rigid-body force and torque lumped on the rod network's nodes (shared by the body terms).

The body terms (:mod:`~frog_sim.core.body_damping`, :mod:`~frog_sim.core.waterline_friction`)
act on the rigid-body motion of eq. 10-12: the centre-of-mass velocity ``V = sum m_i v_i / M``
and the yaw rate from the angular momentum about the COM, ``r = sum m_i (r_i x v_i) / I``,
``I = sum m_i |r_i|^2`` (``r_i`` from the COM, ``v_i`` relative to ``V``). A force F and a
torque N are spread over the nodes by mass, ``f_i = m_i F / M + m_i N perp(r_i) / I``, which
sums to exactly F and N and whose power is ``F . V + N r``.
"""
from __future__ import annotations

from numba import njit


@njit(cache=True, inline='always', error_model='numpy')
def rigid_motion(x, v, mass):
    """(M, c_x, c_y, V_x, V_y, I, r): total mass [kg], COM [m], COM velocity [m/s],
    inertia about the COM [kg m^2] and yaw rate [rad/s] of nodes ``x``, ``v`` (2N,)."""
    n = mass.shape[0]
    mt = 0.0
    cx = 0.0
    cy = 0.0
    vx = 0.0
    vy = 0.0
    for i in range(n):
        m = mass[i]
        mt += m
        cx += m * x[2 * i]
        cy += m * x[2 * i + 1]
        vx += m * v[2 * i]
        vy += m * v[2 * i + 1]
    cx /= mt
    cy /= mt
    vx /= mt
    vy /= mt
    inertia = 0.0
    ang = 0.0
    for i in range(n):
        m = mass[i]
        rx = x[2 * i] - cx
        ry = x[2 * i + 1] - cy
        inertia += m * (rx * rx + ry * ry)
        ang += m * (rx * (v[2 * i + 1] - vy) - ry * (v[2 * i] - vx))
    return mt, cx, cy, vx, vy, inertia, ang / inertia


@njit(cache=True, inline='always', error_model='numpy')
def spread_wrench(x, mass, mt, cx, cy, inertia, fx, fy, torque, out):
    """Nodal forces (2N,) [N] into ``out`` that sum to the force (fx, fy) [N] and the torque
    ``torque`` [N m] about the COM (cx, cy), by mass."""
    for i in range(mass.shape[0]):
        m = mass[i]
        rx = x[2 * i] - cx
        ry = x[2 * i + 1] - cy
        out[2 * i] = m * fx / mt - m * torque * ry / inertia
        out[2 * i + 1] = m * fy / mt + m * torque * rx / inertia
