"""Small generic integrator terms: given nodal forces (explicit) and tethers (implicit).

Examples of terms added to the integrator only through
:mod:`~frog_sim.core.element_sets` (a kernel, a namedtuple of arrays, one
registration), used by the tests of the element sets. Term classes must be defined in an
importable module like this one: numba's cache index of the integrator stores their types.
"""
from __future__ import annotations

from collections import namedtuple

from numba import njit

from .element_sets import register_explicit_term, register_implicit_term

NodalForceTerm = namedtuple('NodalForceTerm', 'force')
NodalForceTerm.__doc__ = """Given force on each element's DOFs (M, k) [N] (explicit; e.g. one element per
node with DOF map (N, 2))."""


@njit(cache=True)
def nodal_force_term(term, m, xe, ve, force):
    """Explicit-term kernel of :class:`NodalForceTerm`."""
    for p in range(xe.shape[0]):
        force[p] = term.force[m, p]
    return True


register_explicit_term(NodalForceTerm, nodal_force_term)

TetherTerm = namedtuple('TetherTerm', 'anchor stiffness')
TetherTerm.__doc__ = """Linear spring tying each node to an anchor point, E = k |x - x0|^2 / 2 (implicit;
one element per node, DOF map (N, 2)): anchors (N, 2) [m], stiffness k (N,) [N/m]."""


@njit(cache=True)
def tether_term(term, m, xe, ve, grad, hess, dgdv, want_jac):
    """Implicit-term kernel of :class:`TetherTerm`: gradient k (x - x0), Hessian k I."""
    k = term.stiffness[m]
    for p in range(2):
        grad[p] = k * (xe[p] - term.anchor[m, p])
        if want_jac:
            for q in range(2):
                hess[p, q] = k if p == q else 0.0


register_implicit_term(TetherTerm, tether_term, n_dofs=2)
