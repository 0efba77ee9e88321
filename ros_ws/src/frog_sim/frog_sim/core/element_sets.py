"""Force and energy terms of the integrator as element sets (paper eq. 6-8).

The residual of a backward-Euler step (eq. 6) and its Jacobian (eq. 8) are sums over
elements. An **element set** groups elements of the same shape:

* ``dofs``, int64 (M, k): the degrees of freedom element ``m`` touches (its DOF map),
  e.g. ``(x_a, y_a, x_b, y_b)`` of an edge or the six DOFs of a bend;
* ``jac_maps``, int32 (2, M, k, k): where entry (p, q) of element m's local Jacobian goes
  in the value array of the numba sparse LU (``[0]``) or of the CSR matrix (``[1]``);
  rows and columns of fixed DOFs point to the trash slot (the last entry);
* ``terms``: a tuple of **term records** that act on these elements. A term record is a
  namedtuple of the arrays its kernel reads (per-element parameters such as the rest
  length and EA, the live arrays the actuation writes); a kernel's scratch space is a
  :func:`stack_array`.

Terms of one set are summed per element, in the order given, before the element is
scattered (as one element loop per set).

Implicit terms (inside Newton) act on elements of a fixed number k of DOFs (``n_dofs`` at
registration) and have a kernel ::

    kernel(term, m, xe, ve, grad, hess, dgdv, want_jac)

with ``xe``, ``ve`` (k,) the element's positions and velocities ``(x - x_k) / h``; it
writes ``grad`` (k,), the term's part of the residual F (``dE/dx`` of an energy, ``-f``
of a force), and with ``want_jac`` ``hess`` (k, k) = ``d grad / dx`` and, for a
velocity-dependent term, ``dgdv`` (k, k) = ``d grad / dv``: the Jacobian gets
``hess + dgdv / h`` (eq. 8, ``d2E/dx2 - df_d/dx - (1/h) df_d/dv``). Velocity-dependent
(dissipative) terms are left out of the static problem.

Explicit terms (lagged: evaluated once at the start of a step, held over it and added
to the applied force ``f_ext``) live in **explicit sets** with the same ``dofs``, no
Jacobian maps, and a kernel ::

    kernel(term, m, xe, ve, force) -> bool

writing the element's force (k,) [N] at the state of the start of the step; ``False``
means the term is switched off (no force). Forces on fixed DOFs are dropped.

Adding a term: write its kernel and its namedtuple of arrays, register them here with
:func:`register_implicit_term` / :func:`register_explicit_term`, and list it in an
element set of the integrator (``ImplicitEulerIntegrator._element_sets``). The numba
code is specialised per term type at compile time (and cached), so nothing else changes.

Speed (the element loop runs ~4 times per step over every edge and bend): the terms of a
set are unrolled per element with ``literal_unroll`` (a constant trip count: LLVM folds
the switch on the term index into straight-line code), k is a compile-time constant (the
loops over an element's DOFs unroll), the dispatch and the term kernels are inlined in
numba IR (declare kernels ``njit(inline='always')``; large element routines such as
``bend_element`` stay plain calls, which LLVM inlines where they are small: the
residual-only versions), the dispatch keeps ``want_jac`` and ``dynamic`` literal (the
residual-only assembly compiles without Hessian code), and the per-element scratch
arrays are unmanaged stack arrays (:func:`stack_array`): an NRT array handed to an
inlined function in the loop costs an atomic incref/decref per element.

numba's cache checks the source file of a cached function only, not the files of the
functions it calls: after editing a kernel outside ``integrator.py``, delete
``frog_sim/core/__pycache__/*.nb[ic]`` or the integrator keeps running the old kernel.
"""
from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import literal_unroll, njit, types
from numba.core import cgutils
from numba.extending import intrinsic, overload

ElementSet = namedtuple('ElementSet', 'dofs jac_maps terms')
ElementSet.__doc__ = """Implicit element set: DOF map (M, k), Jacobian scatter maps (2, M, k, k) into
the LU [0] / CSR [1] value arrays, and a tuple of term records summed per element."""

ExplicitSet = namedtuple('ExplicitSet', 'dofs terms')
ExplicitSet.__doc__ = """Explicit element set: DOF map (M, k) and a tuple of explicit term records whose
forces are evaluated at the start of each step and added to the applied force."""

MAX_ELEMENT_DOFS = 16    # k of an implicit element set (its per-element scratch lives on the stack)
_MAX_ELEMENT_JAC = MAX_ELEMENT_DOFS * MAX_ELEMENT_DOFS

_IMPLICIT_KERNELS = {}   # term class -> (kernel, velocity dependent, DOFs per element)
_EXPLICIT_KERNELS = {}   # term class -> kernel
# the dispatch overloads are inlined into the element loop (numba IR) and keep literal flags
_JIT_OPTIONS = {'cache': True, 'error_model': 'numpy'}


def register_implicit_term(term_class, kernel, n_dofs, velocity_dependent=False):
    """Register the numba ``kernel`` of the implicit term records of ``term_class``.

    Parameters
    ----------
    term_class : namedtuple class
        The term record, defined at module level in an importable module (numba's cache
        index of the integrator pickles the term types: a class from a script or a test
        file would break loading that cache in other processes).
    kernel : numba dispatcher
        ``kernel(term, m, xe, ve, grad, hess, dgdv, want_jac)``, see the module docstring.
    n_dofs : int
        DOFs of one element (k, at most ``MAX_ELEMENT_DOFS``): the width of the DOF map of
        every element set the term is listed in. A compile-time constant of the assembly,
        so its per-element loops are unrolled.
    velocity_dependent : bool
        The term depends on the velocity (writes ``dgdv``); it is then dynamic only.

    Returns
    -------
    term_class
    """
    n_dofs = int(n_dofs)
    if not 1 <= n_dofs <= MAX_ELEMENT_DOFS:
        raise ValueError(f'n_dofs = {n_dofs} of {term_class.__name__} must be in 1-{MAX_ELEMENT_DOFS}')
    _IMPLICIT_KERNELS[term_class] = (kernel, bool(velocity_dependent), n_dofs)
    return term_class


def register_explicit_term(term_class, kernel):
    """Register the numba ``kernel(term, m, xe, ve, force) -> bool`` of an explicit term."""
    _EXPLICIT_KERNELS[term_class] = kernel
    return term_class


def _implicit_contribution(term, m, xe, ve, inv_h, dynamic, want_jac, g, hm, dv, gl, hl):
    """Add term ``term`` of element ``m`` to the element residual ``gl`` (k,) and Jacobian ``hl`` (k, k)."""
    raise NotImplementedError  # numba only (overloaded below per term class)


@overload(_implicit_contribution, inline='always', prefer_literal=True, jit_options=_JIT_OPTIONS)
def _overload_implicit(term, m, xe, ve, inv_h, dynamic, want_jac, g, hm, dv, gl, hl):
    cls = getattr(term, 'instance_class', None)
    if cls not in _IMPLICIT_KERNELS:
        raise TypeError(f'{term} is not a registered implicit term (register_implicit_term)')
    kernel, velocity_dependent, _ = _IMPLICIT_KERNELS[cls]
    if velocity_dependent:
        def impl(term, m, xe, ve, inv_h, dynamic, want_jac, g, hm, dv, gl, hl):
            if not dynamic:
                return
            kernel(term, m, xe, ve, g, hm, dv, want_jac)
            k = xe.shape[0]
            for p in range(k):
                gl[p] += g[p]
                if want_jac:
                    for q in range(k):
                        hl[p, q] += hm[p, q] + dv[p, q] * inv_h
    else:
        def impl(term, m, xe, ve, inv_h, dynamic, want_jac, g, hm, dv, gl, hl):
            kernel(term, m, xe, ve, g, hm, dv, want_jac)
            k = xe.shape[0]
            for p in range(k):
                gl[p] += g[p]
                if want_jac:
                    for q in range(k):
                        hl[p, q] += hm[p, q]
    return impl


def _explicit_contribution(term, m, xe, ve, force):
    """Force of explicit term ``term`` on element ``m``; returns False if it is off."""
    raise NotImplementedError  # numba only


@overload(_explicit_contribution, inline='always', prefer_literal=True, jit_options=_JIT_OPTIONS)
def _overload_explicit(term, m, xe, ve, force):
    cls = getattr(term, 'instance_class', None)
    if cls not in _EXPLICIT_KERNELS:
        raise TypeError(f'{term} is not a registered explicit term (register_explicit_term)')
    kernel = _EXPLICIT_KERNELS[cls]

    def impl(term, m, xe, ve, force):
        return kernel(term, m, xe, ve, force)
    return impl


def _term_traits(terms):
    """(DOFs per element, any term velocity dependent) of a tuple of terms: compile-time constants."""
    raise NotImplementedError  # numba only


@overload(_term_traits, inline='always', jit_options=_JIT_OPTIONS)
def _overload_term_traits(terms):
    if len(terms) == 0:
        raise TypeError('an element set needs at least one term')
    traits = []
    for t in terms:
        cls = getattr(t, 'instance_class', None)
        if cls not in _IMPLICIT_KERNELS:
            raise TypeError(f'{t} is not a registered implicit term (register_implicit_term)')
        traits.append(_IMPLICIT_KERNELS[cls][1:])
    widths = {n for _, n in traits}
    if len(widths) != 1:
        raise TypeError(f'the terms {terms} of one element set act on different numbers of DOFs {widths}')
    width = widths.pop()
    if any(v for v, _ in traits):
        return lambda terms: (width, True)
    return lambda terms: (width, False)


@intrinsic
def stack_array(typingctx, shape, capacity):
    """Scratch float64 C array of ``shape`` (a tuple) on the stack of the compiled function,
    ``capacity`` (an int literal) elements; numba only. The caller guarantees that the
    shape fits (checked at compile time when the shape is literal).

    Unmanaged (no NRT meminfo): handed to a kernel inside the element loop, it costs no
    reference counting (an NRT array there gets an atomic incref/decref per element and
    call), and it is never freed. Valid until the compiled function that lowers the call
    (after numba's inlining: the element-set assembly) returns; never return it. Kernels
    use it for their own scratch space (``stack_array((3, 4, 4), 48)``).
    """
    if not (isinstance(capacity, types.IntegerLiteral) and isinstance(shape, types.BaseTuple)
            and all(isinstance(dim, types.Integer) for dim in shape)):
        return None
    if all(isinstance(dim, types.IntegerLiteral) for dim in shape):
        size = int(np.prod([dim.literal_value for dim in shape]))
        if size > capacity.literal_value:
            raise TypeError(f'stack_array: shape {shape} needs {size} elements, capacity {capacity.literal_value}')
    arrty = types.Array(types.float64, len(shape), 'C')

    def codegen(context, builder, sig, args):
        data = cgutils.alloca_once(builder, context.get_value_type(types.float64), size=capacity.literal_value)
        dims = cgutils.unpack_tuple(builder, args[0])
        itemsize = context.get_constant(types.intp, 8)
        strides = []
        stride = itemsize
        for dim in reversed(dims):
            strides.insert(0, stride)
            stride = builder.mul(stride, dim)
        ary = context.make_array(arrty)(context, builder)
        context.populate_array(ary, data=data, shape=dims, strides=strides, itemsize=itemsize, meminfo=None)
        return ary._getvalue()
    return arrty(shape, capacity), codegen


@njit(cache=True, error_model='numpy')
def assemble_element_set(es, target, x, x_prev, inv_h, dynamic, resid, data, want_jac):
    """Add the residual (eq. 6) and Jacobian (eq. 8) entries of one element set.

    ``target`` 0 scatters into the LU value array, 1 into the CSR one (``data``);
    ``resid`` (2N,) is accumulated. Per element: gather its DOFs (velocities only if a
    term needs them), sum its terms in their order (unrolled at compile time), scatter.
    """
    dofs = es.dofs
    terms = es.terms
    n_el = dofs.shape[0]
    k, velocity_dependent = _term_traits(terms)
    if dofs.shape[1] != k:
        raise ValueError('the DOF map of an element set is not as wide as its terms\' n_dofs')
    jmap = es.jac_maps[target]
    need_v = dynamic and velocity_dependent
    xe = stack_array((k,), MAX_ELEMENT_DOFS)
    ve = stack_array((k,), MAX_ELEMENT_DOFS)
    g = stack_array((k,), MAX_ELEMENT_DOFS)
    gl = stack_array((k,), MAX_ELEMENT_DOFS)
    hm = stack_array((k, k), _MAX_ELEMENT_JAC)
    dv = stack_array((k, k), _MAX_ELEMENT_JAC)
    hl = stack_array((k, k), _MAX_ELEMENT_JAC)
    for p in range(k):
        ve[p] = 0.0
        for q in range(k):
            hm[p, q] = 0.0
            dv[p, q] = 0.0
    for m in range(n_el):
        for p in range(k):
            d = dofs[m, p]
            xe[p] = x[d]
            if need_v:
                ve[p] = (x[d] - x_prev[d]) * inv_h
            gl[p] = 0.0
            if want_jac:
                for q in range(k):
                    hl[p, q] = 0.0
        for term in literal_unroll(terms):
            _implicit_contribution(term, m, xe, ve, inv_h, dynamic, want_jac, g, hm, dv, gl, hl)
        for p in range(k):
            resid[dofs[m, p]] += gl[p]
        if want_jac:
            for p in range(k):
                for q in range(k):
                    data[jmap[m, p, q]] += hl[p, q]


@njit(cache=True, error_model='numpy')
def add_explicit_set(es, x, v, fixed, f_total):
    """Add the forces of one explicit set at state (x, v) to ``f_total`` (free DOFs only)."""
    dofs = es.dofs
    k = dofs.shape[1]
    xe = np.empty(k)
    ve = np.empty(k)
    force = np.empty(k)
    for m in range(dofs.shape[0]):
        for p in range(k):
            xe[p] = x[dofs[m, p]]
            ve[p] = v[dofs[m, p]]
        for term in literal_unroll(es.terms):
            if _explicit_contribution(term, m, xe, ve, force):
                for p in range(k):
                    d = dofs[m, p]
                    if not fixed[d]:
                        f_total[d] += force[p]


def scatter_maps(dofs, fixed, csr_map, lu_map, lu_trash, csr_trash):
    """Jacobian maps (2, M, k, k) int32 of a set: [0] into the LU, [1] into the CSR values,
    with rows/columns of ``fixed`` DOFs sent to the trash slots."""
    maps = np.stack([np.asarray(lu_map), np.asarray(csr_map)]).astype(np.int32)
    f = fixed[dofs]
    mask = f[:, :, None] | f[:, None, :]
    maps[0][mask] = lu_trash
    maps[1][mask] = csr_trash
    return maps


def element_set_maps(pattern, dofs, fixed):
    """Jacobian maps (2, M, k, k) of a new element set with DOF map ``dofs`` (M, k) in an
    existing :class:`~frog_sim.core.linear_algebra.JacobianPattern`.

    Raises
    ------
    ValueError
        If an element couples two DOFs that the pattern has no entry for.
    """
    dofs = np.ascontiguousarray(dofs, dtype=np.int64)
    k = dofs.shape[1]
    rows = np.repeat(dofs, k, axis=1).ravel()
    cols = np.tile(dofs, (1, k)).ravel()
    csr = np.empty(rows.size, dtype=np.int64)
    lu = np.empty(rows.size, dtype=np.int64)
    plan = pattern.lu_plan
    for i, (r, c) in enumerate(zip(rows.tolist(), cols.tolist())):
        lo, hi = pattern.indptr[r], pattern.indptr[r + 1]
        j = lo + int(np.searchsorted(pattern.indices[lo:hi], c))
        if j >= hi or pattern.indices[j] != c:
            raise ValueError(f'DOFs {r} and {c} are not coupled in the Jacobian pattern')
        csr[i] = j
        lu[i] = plan.index_of[(int(plan.iperm[r]), int(plan.iperm[c]))]
    shape = (dofs.shape[0], k, k)
    return scatter_maps(dofs, fixed, csr.reshape(shape), lu.reshape(shape), plan.nnz, pattern.nnz)
