"""Fluid forces: quadratic drag (paper eq. 1-2) and added mass (paper eq. 3-4).

Drag is evaluated per edge (element class = body or limb) at the edge's mid-point
velocity ``v = (v_a + v_b) / 2`` in the edge's own tangent/normal frame and lumped
half to each end node:

    f = -1/2 rho_f D dl |v| C_d v,      C_d = C_t t t^T + C_n n n^T        (eq. 1-2)

so a joint node collects drag from the edges of every rod it belongs to, and the
total drag on a rigidly translating straight rod is exactly 1/2 rho C D L |v| v.
The Jacobian w.r.t. both the velocity and the positions (through the tangent t)
is returned so that Newton (eq. 7-8) converges quadratically.

Added mass (eq. 3) is folded into the lumped mass (eq. 4): each edge contributes
``(rho_l + C_a rho_f pi D^2 / 4) dl / 2`` to both of its end nodes, where rho_l is the
structural linear density.
"""
from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import njit

from .element_sets import register_implicit_term


def drag_prefactors(network, fluid_density: float):
    """Per-edge constants ``1/2 rho_f C D dl`` for the normal and tangent directions.

    Parameters
    ----------
    network : RodNetwork
    fluid_density : float
        rho_f [kg/m^3].

    Returns
    -------
    normal, tangent : ndarray, shape (E,)
        [kg/m] (force = prefactor * |v| * v-component).
    """
    base = 0.5 * fluid_density * network.edge_diameter * network.edge_rest_length
    return base * network.edge_drag_normal, base * network.edge_drag_tangent


def lumped_masses(network, fluid_density: float, added_mass_coefficient: float,
                  added_mass_diameter=None, lumping_factor: float = 1.0) -> np.ndarray:
    """Revised nodal masses including added mass (paper eq. 3-4).

    Parameters
    ----------
    network : RodNetwork
    fluid_density : float
        rho_f [kg/m^3].
    added_mass_coefficient : float
        C_a [-].
    added_mass_diameter : ndarray, shape (E,), optional
        D of eq. 3 per edge (default: ``network.edge_diameter``).
    lumping_factor : float
        Share of the normal added mass lumped isotropically (1 = paper eq. 4; 0.5 = the
        direction average of a section with added mass only normal to itself).

    Returns
    -------
    ndarray, shape (N,)
        m_i [kg].
    """
    diameter = network.edge_diameter if added_mass_diameter is None else np.asarray(added_mass_diameter)
    per_length = (network.edge_linear_density
                  + lumping_factor * added_mass_coefficient * fluid_density * np.pi * diameter ** 2 / 4.0)
    half = 0.5 * per_length * network.edge_rest_length
    mass = np.zeros(network.n_nodes)
    np.add.at(mass, network.edges[:, 0], half)
    np.add.at(mass, network.edges[:, 1], half)
    if np.any(mass <= 0):
        bad = int(np.argmin(mass))
        raise ValueError(f'node {bad} has mass {mass[bad]!r} kg; every node needs an edge with mass')
    return mass


@njit(cache=True, fastmath=True, error_model='numpy')
def drag_element(xa0, xa1, xb0, xb1, va0, va1, vb0, vb1, cn, ct, force, dfdv, dfdx,
                 want_jacobian=True):
    """Drag on one edge, lumped to its nodes.

    Writes ``force`` (4,) [N] on (xa, ya, xb, yb) and, if ``want_jacobian``, ``dfdv``
    (4, 4) [N s/m] and ``dfdx`` (4, 4) [N/m] (derivatives of that force w.r.t. node
    velocities and positions). ``cn``/``ct`` are 1/2 rho C D dl for the normal/tangent
    direction.
    """
    e0 = xb0 - xa0
    e1 = xb1 - xa1
    length = np.sqrt(e0 * e0 + e1 * e1)
    t0 = e0 / length
    t1 = e1 / length
    v0 = 0.5 * (va0 + vb0)
    v1 = 0.5 * (va1 + vb1)
    speed = np.sqrt(v0 * v0 + v1 * v1)
    vt = t0 * v0 + t1 * v1
    dc = ct - cn
    # f = -|v| (cn v + (ct - cn) t (t.v))          (eq. 1-2)
    f0 = -speed * (cn * v0 + dc * t0 * vt)
    f1 = -speed * (cn * v1 + dc * t1 * vt)
    force[0] = 0.5 * f0
    force[1] = 0.5 * f1
    force[2] = 0.5 * f0
    force[3] = 0.5 * f1
    if not want_jacobian:
        return
    # df/dv_mid = -[cn (|v| I + v v^T/|v|) + dc (|v| t t^T + t (t.v) v^T/|v|)]
    inv_speed = 1.0 / speed if speed > 1e-300 else 0.0
    g00 = -(cn * (speed + v0 * v0 * inv_speed) + dc * (speed * t0 * t0 + t0 * vt * v0 * inv_speed))
    g01 = -(cn * (v0 * v1 * inv_speed) + dc * (speed * t0 * t1 + t0 * vt * v1 * inv_speed))
    g10 = -(cn * (v1 * v0 * inv_speed) + dc * (speed * t1 * t0 + t1 * vt * v0 * inv_speed))
    g11 = -(cn * (speed + v1 * v1 * inv_speed) + dc * (speed * t1 * t1 + t1 * vt * v1 * inv_speed))
    # df/de = -|v| dc [(t.v) I + t v^T] P / l,  P = I - t t^T
    a00 = vt + t0 * v0
    a01 = t0 * v1
    a10 = t1 * v0
    a11 = vt + t1 * v1
    p00 = 1.0 - t0 * t0
    p01 = -t0 * t1
    p11 = 1.0 - t1 * t1
    k = -speed * dc / length
    ge00 = k * (a00 * p00 + a01 * p01)
    ge01 = k * (a00 * p01 + a01 * p11)
    ge10 = k * (a10 * p00 + a11 * p01)
    ge11 = k * (a10 * p01 + a11 * p11)
    # node force = f/2 ; v_mid = (va + vb)/2 ; e = xb - xa
    for r in range(2):
        o = 2 * r
        dfdv[o, 0] = 0.25 * g00
        dfdv[o, 1] = 0.25 * g01
        dfdv[o + 1, 0] = 0.25 * g10
        dfdv[o + 1, 1] = 0.25 * g11
        dfdx[o, 0] = -0.5 * ge00
        dfdx[o, 1] = -0.5 * ge01
        dfdx[o + 1, 0] = -0.5 * ge10
        dfdx[o + 1, 1] = -0.5 * ge11
        for p in range(2):
            for q in range(2):
                dfdv[o + p, 2 + q] = dfdv[o + p, q]
                dfdx[o + p, 2 + q] = -dfdx[o + p, q]


@njit(cache=True, error_model='numpy')
def drag_forces(x, v, edges, cn, ct, force_out):
    """Total drag force (2N,) [N] on all nodes (no derivatives)."""
    for k in range(force_out.shape[0]):
        force_out[k] = 0.0
    f4 = np.empty(4)
    jv = np.empty((4, 4))
    jx = np.empty((4, 4))
    for m in range(edges.shape[0]):
        a = edges[m, 0]
        b = edges[m, 1]
        drag_element(x[2 * a], x[2 * a + 1], x[2 * b], x[2 * b + 1], v[2 * a], v[2 * a + 1],
                     v[2 * b], v[2 * b + 1], cn[m], ct[m], f4, jv, jx)
        force_out[2 * a] += f4[0]
        force_out[2 * a + 1] += f4[1]
        force_out[2 * b] += f4[2]
        force_out[2 * b + 1] += f4[3]


DragTerm = namedtuple('DragTerm', 'normal tangent')
DragTerm.__doc__ = """Quadratic drag of eq. 1-2 on the edges (an element = the 4 DOFs of an edge):
prefactors 1/2 rho_f C D dl for the normal and tangent directions (E,) [kg/m]."""


@njit(cache=True, inline='always', error_model='numpy')
def drag_term(term, m, xe, ve, grad, hess, dgdv, want_jac):
    """Implicit-term kernel of :class:`DragTerm`: ``-f_d``, ``-df_d/dx``, ``-df_d/dv`` (eq. 6, 8)."""
    drag_element(xe[0], xe[1], xe[2], xe[3], ve[0], ve[1], ve[2], ve[3], term.normal[m],
                 term.tangent[m], grad, dgdv, hess, want_jac)
    for p in range(4):
        grad[p] = -grad[p]
        if want_jac:
            for q in range(4):
                hess[p, q] = -hess[p, q]
                dgdv[p, q] = -dgdv[p, q]


register_implicit_term(DragTerm, drag_term, n_dofs=4, velocity_dependent=True)
