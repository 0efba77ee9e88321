"""Discrete elastic energies of the rod network with analytic gradients and Hessians.

Paper ("Energy, Forces, and Equations of Motion"):

* stretching ``E_s = EA eps^2 dl / 2`` with ``eps = |x_b - x_a| / dl - 1``;
* bending ``E_b = EI (kappa - kappa0)^2 dl / 2`` with ``kappa = 2 tan(phi/2) / dl`` and
  ``phi`` the signed turning angle between consecutive edges.

With ``e1 = x_i - x_{i-1}``, ``e2 = x_{i+1} - x_i``, ``c = e1 x e2`` and
``D = |e1||e2| + e1.e2`` the identity ``tan(phi/2) = c / D`` gives a rational expression
whose first and second derivatives are written out below (no atan2 in the kernels).

The kernels are numba-compiled (``cache=True``) and work on flat state vectors
``x`` of shape (2N,) ordered ``[x0, y0, x1, y1, ...]``.
"""
from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import njit

from .element_sets import register_implicit_term, stack_array


@njit(cache=True, fastmath=True, error_model='numpy')
def stretch_element(xa0, xa1, xb0, xb1, rest_length, ea, grad, hess, want_hess=True):
    """Energy of one edge; writes gradient (4,) and (if ``want_hess``) Hessian (4, 4)
    w.r.t. (xa, ya, xb, yb). (fastmath: no NaN checks in here; callers check results.)"""
    e0 = xb0 - xa0
    e1 = xb1 - xa1
    length = np.sqrt(e0 * e0 + e1 * e1)
    eps = length / rest_length - 1.0
    energy = 0.5 * ea * eps * eps * rest_length
    t0 = e0 / length
    t1 = e1 / length
    # dE/de = EA eps t
    g0 = ea * eps * t0
    g1 = ea * eps * t1
    grad[0] = -g0
    grad[1] = -g1
    grad[2] = g0
    grad[3] = g1
    if not want_hess:
        return energy
    # d2E/de2 = EA/l0 t t^T + EA eps / l (I - t t^T)
    a = ea / rest_length
    b = ea * eps / length
    k00 = a * t0 * t0 + b * (1.0 - t0 * t0)
    k01 = a * t0 * t1 - b * t0 * t1
    k11 = a * t1 * t1 + b * (1.0 - t1 * t1)
    for p in range(2):
        for q in range(2):
            kpq = k00 if p + q == 0 else (k11 if p + q == 2 else k01)
            hess[p, q] = kpq
            hess[p + 2, q + 2] = kpq
            hess[p, q + 2] = -kpq
            hess[p + 2, q] = -kpq
    return energy


@njit(cache=True, inline='always')
def _d2c(p, q):
    """Second derivative of c = e1 x e2 w.r.t. u = (e1, e2) (constant)."""
    if (p == 0 and q == 3) or (p == 3 and q == 0):
        return 1.0
    if (p == 1 and q == 2) or (p == 2 and q == 1):
        return -1.0
    return 0.0


@njit(cache=True, fastmath=True, error_model='numpy')
def bend_element(xa0, xa1, xb0, xb1, xc0, xc1, dl, ei, kappa0, grad, hess, work, want_hess=True):
    """Energy of one bending triple; writes gradient (6,) and (if ``want_hess``) Hessian (6, 6).

    Degrees of freedom are ordered (xa, ya, xb, yb, xc, yc) with b the middle node.
    ``work`` is a scratch array of shape (3, 4, 4) (no allocation in the hot loop).
    """
    u0 = xb0 - xa0
    u1 = xb1 - xa1
    u2 = xc0 - xb0
    u3 = xc1 - xb1
    n1 = np.sqrt(u0 * u0 + u1 * u1)
    n2 = np.sqrt(u2 * u2 + u3 * u3)
    c = u0 * u3 - u1 * u2
    dd = n1 * n2 + u0 * u2 + u1 * u3
    kappa = 2.0 * c / (dd * dl)
    diff = kappa - kappa0
    energy = 0.5 * ei * diff * diff * dl
    vec = work[0]          # rows: dc, dD, dk, gu
    dc = vec[0]
    dD = vec[1]
    dk = vec[2]
    gu = vec[3]
    dc[0] = u3
    dc[1] = -u2
    dc[2] = -u1
    dc[3] = u0
    t1x = u0 / n1
    t1y = u1 / n1
    t2x = u2 / n2
    t2y = u3 / n2
    dD[0] = n2 * t1x + u2
    dD[1] = n2 * t1y + u3
    dD[2] = n1 * t2x + u0
    dD[3] = n1 * t2y + u1
    s = 2.0 / dl
    inv = 1.0 / dd
    w = ei * dl
    for p in range(4):
        dk[p] = s * (dc[p] * inv - c * dD[p] * inv * inv)
        gu[p] = w * diff * dk[p]
    # chain rule: e1 = xb - xa, e2 = xc - xb
    for comp in range(2):
        grad[comp] = -gu[comp]
        grad[2 + comp] = gu[comp] - gu[2 + comp]
        grad[4 + comp] = gu[2 + comp]
    if not want_hess:
        return energy
    d2D = work[1]
    hu = work[2]
    r12 = n2 / n1
    r21 = n1 / n2
    d2D[0, 0] = r12 * (1.0 - t1x * t1x)
    d2D[0, 1] = -r12 * t1x * t1y
    d2D[1, 0] = d2D[0, 1]
    d2D[1, 1] = r12 * (1.0 - t1y * t1y)
    d2D[2, 2] = r21 * (1.0 - t2x * t2x)
    d2D[2, 3] = -r21 * t2x * t2y
    d2D[3, 2] = d2D[2, 3]
    d2D[3, 3] = r21 * (1.0 - t2y * t2y)
    d2D[0, 2] = t1x * t2x + 1.0
    d2D[0, 3] = t1x * t2y
    d2D[1, 2] = t1y * t2x
    d2D[1, 3] = t1y * t2y + 1.0
    d2D[2, 0] = d2D[0, 2]
    d2D[3, 0] = d2D[0, 3]
    d2D[2, 1] = d2D[1, 2]
    d2D[3, 1] = d2D[1, 3]
    inv2 = inv * inv
    inv3 = inv2 * inv
    for p in range(4):
        for q in range(p, 4):
            d2k = s * (_d2c(p, q) * inv
                       - (dc[p] * dD[q] + dD[p] * dc[q]) * inv2
                       + 2.0 * c * dD[p] * dD[q] * inv3
                       - c * d2D[p, q] * inv2)
            val = w * (dk[p] * dk[q] + diff * d2k)
            hu[p, q] = val
            hu[q, p] = val
    # H_x = B^T H_u B, done blockwise on 2x2 blocks
    for p in range(2):
        for q in range(2):
            h11 = hu[p, q]
            h12 = hu[p, q + 2]
            h21 = hu[p + 2, q]
            h22 = hu[p + 2, q + 2]
            hess[p, q] = h11
            hess[p, 2 + q] = -h11 + h12
            hess[p, 4 + q] = -h12
            hess[2 + p, q] = -h11 + h21
            hess[2 + p, 2 + q] = h11 - h12 - h21 + h22
            hess[2 + p, 4 + q] = h12 - h22
            hess[4 + p, q] = -h21
            hess[4 + p, 2 + q] = h21 - h22
            hess[4 + p, 4 + q] = h22
    return energy


# ---------------------------------------------------------------- integrator terms
StretchTerm = namedtuple('StretchTerm', 'rest_length stiffness')
StretchTerm.__doc__ = """Stretching energy E_s of the edges (an element = the 4 DOFs of an edge):
rest lengths dl (E,) [m] and EA (E,) [N] (the live array the actuation writes)."""

BendTerm = namedtuple('BendTerm', 'length stiffness natural_curvature')
BendTerm.__doc__ = """Bending energy E_b of the bends (an element = the 6 DOFs of a node triple):
Voronoi lengths dl (B,) [m], EI (B,) [N m^2], kappa0 (B,) [1/m] (live arrays of the
actuation)."""


@njit(cache=True, inline='always', error_model='numpy')
def stretch_term(term, m, xe, ve, grad, hess, dgdv, want_jac):
    """Implicit-term kernel of :class:`StretchTerm` (gradient and Hessian of E_s, eq. 8)."""
    stretch_element(xe[0], xe[1], xe[2], xe[3], term.rest_length[m], term.stiffness[m], grad, hess,
                    want_jac)


@njit(cache=True, inline='always', error_model='numpy')
def bend_term(term, m, xe, ve, grad, hess, dgdv, want_jac):
    """Implicit-term kernel of :class:`BendTerm` (gradient and Hessian of E_b, eq. 8)."""
    work = stack_array((3, 4, 4), 48)
    bend_element(xe[0], xe[1], xe[2], xe[3], xe[4], xe[5], term.length[m], term.stiffness[m],
                 term.natural_curvature[m], grad, hess, work, want_jac)


register_implicit_term(StretchTerm, stretch_term, n_dofs=4)
register_implicit_term(BendTerm, bend_term, n_dofs=6)


@njit(cache=True, error_model='numpy')
def elastic_energy_gradient(x, edges, rest_length, ea, bends, bend_length, ei, kappa0, grad_out):
    """Total elastic energy [J]; accumulates the gradient (2N,) [N] into ``grad_out``."""
    for k in range(grad_out.shape[0]):
        grad_out[k] = 0.0
    g4 = np.empty(4)
    h4 = np.empty((4, 4))
    g6 = np.empty(6)
    h6 = np.empty((6, 6))
    work = np.empty((3, 4, 4))
    energy = 0.0
    for m in range(edges.shape[0]):
        a = edges[m, 0]
        b = edges[m, 1]
        energy += stretch_element(x[2 * a], x[2 * a + 1], x[2 * b], x[2 * b + 1],
                                  rest_length[m], ea[m], g4, h4)
        grad_out[2 * a] += g4[0]
        grad_out[2 * a + 1] += g4[1]
        grad_out[2 * b] += g4[2]
        grad_out[2 * b + 1] += g4[3]
    for m in range(bends.shape[0]):
        i = bends[m, 0]
        j = bends[m, 1]
        k = bends[m, 2]
        energy += bend_element(x[2 * i], x[2 * i + 1], x[2 * j], x[2 * j + 1], x[2 * k],
                               x[2 * k + 1], bend_length[m], ei[m], kappa0[m], g6, h6, work, False)
        grad_out[2 * i] += g6[0]
        grad_out[2 * i + 1] += g6[1]
        grad_out[2 * j] += g6[2]
        grad_out[2 * j + 1] += g6[3]
        grad_out[2 * k] += g6[4]
        grad_out[2 * k + 1] += g6[5]
    return energy


@njit(cache=True, error_model='numpy')
def elastic_hessian_dense(x, edges, rest_length, ea, bends, bend_length, ei, kappa0, hess_out):
    """Dense Hessian (2N, 2N) of the elastic energy [N/m] (tests and small problems)."""
    hess_out[:, :] = 0.0
    g4 = np.empty(4)
    h4 = np.empty((4, 4))
    g6 = np.empty(6)
    h6 = np.empty((6, 6))
    dof4 = np.empty(4, dtype=np.int64)
    dof6 = np.empty(6, dtype=np.int64)
    work = np.empty((3, 4, 4))
    for m in range(edges.shape[0]):
        a = edges[m, 0]
        b = edges[m, 1]
        stretch_element(x[2 * a], x[2 * a + 1], x[2 * b], x[2 * b + 1], rest_length[m], ea[m],
                        g4, h4)
        dof4[0] = 2 * a
        dof4[1] = 2 * a + 1
        dof4[2] = 2 * b
        dof4[3] = 2 * b + 1
        for p in range(4):
            for q in range(4):
                hess_out[dof4[p], dof4[q]] += h4[p, q]
    for m in range(bends.shape[0]):
        for r in range(3):
            dof6[2 * r] = 2 * bends[m, r]
            dof6[2 * r + 1] = 2 * bends[m, r] + 1
        bend_element(x[dof6[0]], x[dof6[1]], x[dof6[2]], x[dof6[3]], x[dof6[4]], x[dof6[5]],
                     bend_length[m], ei[m], kappa0[m], g6, h6, work, True)
        for p in range(6):
            for q in range(6):
                hess_out[dof6[p], dof6[q]] += h6[p, q]


def network_energy_gradient(network, x_flat, kappa0=None, ei=None, ea=None):
    """Elastic energy and gradient of a :class:`RodNetwork` at ``x_flat`` (2N,).

    Parameters
    ----------
    network : RodNetwork
    x_flat : ndarray, shape (2N,)
        Node positions [m], ordered x0, y0, x1, y1, ...
    kappa0, ei, ea : ndarray, optional
        Overrides of the natural curvature (B,), EI (B,), EA (E,).

    Returns
    -------
    energy : float
        [J]
    gradient : ndarray, shape (2N,)
        dE/dx [N] (the internal force is its negative).
    """
    grad = np.zeros(network.n_dof)
    energy = elastic_energy_gradient(
        np.ascontiguousarray(x_flat, dtype=float), network.edges, network.edge_rest_length,
        network.edge_stretching_stiffness if ea is None else ea, network.bends,
        network.bend_length, network.bend_stiffness if ei is None else ei,
        network.bend_natural_curvature if kappa0 is None else kappa0, grad)
    return energy, grad


def network_hessian(network, x_flat, kappa0=None, ei=None, ea=None) -> np.ndarray:
    """Dense elastic Hessian (2N, 2N) [N/m] of a :class:`RodNetwork` (for tests, small N)."""
    hess = np.zeros((network.n_dof, network.n_dof))
    elastic_hessian_dense(
        np.ascontiguousarray(x_flat, dtype=float), network.edges, network.edge_rest_length,
        network.edge_stretching_stiffness if ea is None else ea, network.bends,
        network.bend_length, network.bend_stiffness if ei is None else ei,
        network.bend_natural_curvature if kappa0 is None else kappa0, hess)
    return hess
