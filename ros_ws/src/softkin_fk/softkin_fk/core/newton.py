"""Projected Newton for the energy of eq. 9 (all R_w = 1), and its implicit sensitivities.

With the optimal rotation eliminated, each element contributes

    E_i(X) = c_i min_R ||N X_i - T_i R^T||_F^2,     c_i = w_i Vol(V_i),

where T_i is the centred (actuated) rest shape (eq. 6-8). With M = (N X_i)^T T_i = U S V^T
(signed SVD, U and V proper rotations, R = U V^T) the envelope theorem gives

    grad_X E_i = 2 c_i (N X_i - T_i R^T),

and differentiating the rotation (dR = U Omega V^T, Omega_ab = (U^T dM V)_ab - (..)_ba over
s_a + s_b) gives the exact element Hessian

    H_i = 2 c_i (N (x) I_3 - sum_{a<b} g_ab g_ab^T / (s_a + s_b)),   g_ab = T (v_b u_a^T - v_a u_b^T).

H_i is the identity on the centred space minus a PSD term living in span{g_ab} (3-dim), so
its exact PSD projection costs two 3x3 eigen-decompositions: the element Hessians are clamped
there and assembled (numba) into a fixed sparsity pattern whose symbolic Cholesky analysis
(CHOLMOD through cvxopt, supernodal) is done once per mesh. Each Newton step is one numeric
factorisation, one solve and an Armijo backtracking line search on E, so E never increases.

Implicit sensitivities: at a converged shape grad E(x, sigma) = 0, hence
dx/dsigma = -H^{-1} d(grad E)/dsigma (implicit function theorem), with d(grad E)/dsigma
computed analytically (dT/dsigma and the rotation derivative) and the exact Hessian.
"""
from __future__ import annotations

import numba as nb
import numpy as np
import scipy.sparse as sp

from .local_step import actuated_shape, jacobi_sweeps

try:
    from cvxopt import cholmod as _cholmod
    from cvxopt import matrix as _cvx_matrix
    from cvxopt import spmatrix as _cvx_spmatrix
except ImportError:  # pragma: no cover - depends on the environment
    _cholmod = None

_PAIRS = ((0, 1), (0, 2), (1, 2))


@nb.njit(cache=True, inline='always')
def _sym_eig3(A, w, Q):
    """Eigen-decomposition of a symmetric 3x3 ``A`` (overwritten) by cyclic Jacobi:
    eigenvalues ``w`` (unordered), eigenvectors in the columns of ``Q``."""
    for a in range(3):
        for b in range(3):
            Q[a, b] = 1.0 if a == b else 0.0
    scale = abs(A[0, 0]) + abs(A[1, 1]) + abs(A[2, 2]) + abs(A[0, 1]) + abs(A[0, 2]) + abs(A[1, 2])
    jacobi_sweeps(A, Q, 30, 1e-34, scale)
    for a in range(3):
        w[a] = A[a, a]


@nb.njit(cache=True, inline='always')
def _svd3(M, U, s, V, A, w, Q):
    """Signed SVD M = U diag(s) V^T with det U = det V = +1, s0 >= s1 >= |s2| (s2 < 0 for a
    reflection). A, w, Q are scratch. R = U V^T is the rotation of the local step."""
    for a in range(3):
        for b in range(3):
            acc = 0.0
            for c in range(3):
                acc += M[c, a] * M[c, b]
            A[a, b] = acc
    _sym_eig3(A, w, Q)
    # order descending
    i0, i1, i2 = 0, 1, 2
    if w[i0] < w[i1]:
        i0, i1 = i1, i0
    if w[i1] < w[i2]:
        i1, i2 = i2, i1
    if w[i0] < w[i1]:
        i0, i1 = i1, i0
    for c in range(3):
        V[c, 0] = Q[c, i0]
        V[c, 1] = Q[c, i1]
    V[0, 2] = V[1, 0] * V[2, 1] - V[2, 0] * V[1, 1]
    V[1, 2] = V[2, 0] * V[0, 1] - V[0, 0] * V[2, 1]
    V[2, 2] = V[0, 0] * V[1, 1] - V[1, 0] * V[0, 1]
    # u0 = M v0 / |M v0|
    n0 = 0.0
    for c in range(3):
        U[c, 0] = M[c, 0] * V[0, 0] + M[c, 1] * V[1, 0] + M[c, 2] * V[2, 0]
        n0 += U[c, 0] * U[c, 0]
    n0 = np.sqrt(n0)
    if n0 <= 1e-300:
        for a in range(3):
            s[a] = 0.0
            for b in range(3):
                U[a, b] = 1.0 if a == b else 0.0
                V[a, b] = 1.0 if a == b else 0.0
        return
    for c in range(3):
        U[c, 0] /= n0
    d = 0.0
    for c in range(3):
        U[c, 1] = M[c, 0] * V[0, 1] + M[c, 1] * V[1, 1] + M[c, 2] * V[2, 1]
        d += U[c, 1] * U[c, 0]
    n1 = 0.0
    for c in range(3):
        U[c, 1] -= d * U[c, 0]
        n1 += U[c, 1] * U[c, 1]
    n1 = np.sqrt(n1)
    if n1 <= 1e-12 * n0:
        # rank 1: any unit vector orthogonal to u0
        if abs(U[0, 0]) < 0.9:
            e0, e1, e2 = 1.0, 0.0, 0.0
        else:
            e0, e1, e2 = 0.0, 1.0, 0.0
        d = e0 * U[0, 0] + e1 * U[1, 0] + e2 * U[2, 0]
        U[0, 1], U[1, 1], U[2, 1] = e0 - d * U[0, 0], e1 - d * U[1, 0], e2 - d * U[2, 0]
        n1 = np.sqrt(U[0, 1] ** 2 + U[1, 1] ** 2 + U[2, 1] ** 2)
    for c in range(3):
        U[c, 1] /= n1
    U[0, 2] = U[1, 0] * U[2, 1] - U[2, 0] * U[1, 1]
    U[1, 2] = U[2, 0] * U[0, 1] - U[0, 0] * U[2, 1]
    U[2, 2] = U[0, 0] * U[1, 1] - U[1, 0] * U[0, 1]
    for a in range(3):
        acc = 0.0
        for r in range(3):
            for c in range(3):
                acc += U[r, a] * M[r, c] * V[c, a]
        s[a] = acc


@nb.njit(cache=True, inline='always')
def _element_frame(i, x, elements, rest_centred, kind, ratio, X, T, dT, M, U, s, V, A, w, Q):
    """Centred current shape X, actuated shape T (and dT), signed SVD of M = X^T T."""
    k = elements.shape[1]
    for c in range(3):
        m = 0.0
        for j in range(k):
            X[j, c] = x[elements[i, j], c]
            m += X[j, c]
        m /= k
        for j in range(k):
            X[j, c] -= m
    actuated_shape(i, rest_centred, kind, ratio, T, dT)
    for a in range(3):
        for b in range(3):
            acc = 0.0
            for j in range(k):
                acc += X[j, a] * T[j, b]
            M[a, b] = acc
    _svd3(M, U, s, V, A, w, Q)


@nb.njit(cache=True)
def _terms_range(order, start, stop, x, elements, rest_centred, kind, ratios, passive, coef, project,
                 want_hess, scale, energy, grad, hmap, hdata):
    """Elements ``order[start:stop]`` of :func:`element_terms` (scratch allocated here)."""
    n, k = elements.shape
    nk = 3 * k
    X = np.empty((k, 3))
    T = np.empty((k, 3))
    dT = np.empty((k, 3))
    M = np.empty((3, 3))
    U = np.empty((3, 3))
    V = np.empty((3, 3))
    A = np.empty((3, 3))
    Q = np.empty((3, 3))
    s = np.empty(3)
    w = np.empty(3)
    tv = np.empty((3, k))
    G = np.empty((3, nk))      # g_ab flattened (vertex-major, then coordinate)
    Gram = np.empty((3, 3))
    D = np.empty(3)
    F = np.empty((3, nk))
    Z = np.empty((3, 3))
    lam = np.empty(3)
    Ql = np.empty((3, 3))
    eps = 1e-12 * scale * scale
    for ii in range(start, stop):
        i = order[ii]
        if kind != 0 and passive[i]:
            energy[i] = 0.0
            continue
        _element_frame(i, x, elements, rest_centred, kind, ratios[i], X, T, dT, M, U, s, V, A, w, Q)
        c2 = 2.0 * coef[i]
        e = 0.0
        for j in range(k):
            for a in range(3):
                rt = T[j, 0] * (U[a, 0] * V[0, 0] + U[a, 1] * V[0, 1] + U[a, 2] * V[0, 2]) \
                    + T[j, 1] * (U[a, 0] * V[1, 0] + U[a, 1] * V[1, 1] + U[a, 2] * V[1, 2]) \
                    + T[j, 2] * (U[a, 0] * V[2, 0] + U[a, 1] * V[2, 1] + U[a, 2] * V[2, 2])
                r = X[j, a] - rt
                e += r * r
                grad[elements[i, j], a] += c2 * r
        energy[i] = coef[i] * e
        if not want_hess:
            continue
        # T v_m
        for m in range(3):
            for j in range(k):
                tv[m, j] = T[j, 0] * V[0, m] + T[j, 1] * V[1, m] + T[j, 2] * V[2, m]
        for p in range(3):
            a, b = _PAIRS[p]
            sab = s[a] + s[b]
            D[p] = 1.0 / sab if sab > eps else 1.0 / eps
            for j in range(k):
                for c in range(3):
                    G[p, 3 * j + c] = tv[b, j] * U[c, a] - tv[a, j] * U[c, b]
        # H = 2c (N (x) I - sum_c wt_c F_c F_c^T); exact: F = g, wt = D
        if project:
            # orthonormal basis of span{g}: Gram = Ql diag(lam) Ql^T, e_a = sum_b Ql_ba g_b / sqrt(lam_a)
            for p in range(3):
                for q in range(p, 3):
                    acc = 0.0
                    for r in range(nk):
                        acc += G[p, r] * G[q, r]
                    Gram[p, q] = acc
                    Gram[q, p] = acc
            # most elements are already PSD: K = Gram - Gram D Gram PSD <=> the restriction is
            # (3x3 Cholesky test); then the exact Hessian is its own projection
            psd = True
            for a in range(3):
                for b in range(3):
                    acc = 0.0
                    for m in range(3):
                        acc += Gram[a, m] * D[m] * Gram[m, b]
                    Z[a, b] = Gram[a, b] - acc
            tr = Gram[0, 0] + Gram[1, 1] + Gram[2, 2]
            l00 = Z[0, 0]
            if l00 < -1e-12 * tr:
                psd = False
            elif l00 > 1e-14 * tr:
                l10 = Z[1, 0] / np.sqrt(l00)
                l20 = Z[2, 0] / np.sqrt(l00)
                d11 = Z[1, 1] - l10 * l10
                if d11 < -1e-12 * tr:
                    psd = False
                elif d11 > 1e-14 * tr:
                    l21 = (Z[2, 1] - l20 * l10) / np.sqrt(d11)
                    if Z[2, 2] - l20 * l20 - l21 * l21 < -1e-12 * tr:
                        psd = False
                else:
                    psd = False
            else:
                psd = False
            if psd:
                for cc in range(3):
                    for r in range(nk):
                        F[cc, r] = G[cc, r]
        if project and not psd:
            _sym_eig3(Gram, lam, Ql)
            lmax = max(lam[0], max(lam[1], lam[2]))
            # restricted to the span: Z = I - B, B_ab = sqrt(lam_a lam_b) sum_m D_m Ql_ma Ql_mb
            for a in range(3):
                for b in range(3):
                    if lam[a] > 1e-10 * lmax and lam[b] > 1e-10 * lmax:
                        acc = 0.0
                        for m in range(3):
                            acc += D[m] * Ql[m, a] * Ql[m, b]
                        Z[a, b] = (1.0 if a == b else 0.0) - np.sqrt(lam[a] * lam[b]) * acc
                    else:
                        Z[a, b] = 0.0
            for a in range(3):
                if not lam[a] > 1e-10 * lmax:
                    Z[a, a] = 1.0  # not in the span: nothing subtracted
            _sym_eig3(Z, w, Q)
            # f_c = sum_a Q_ac e_a; clamping eigenvalue z_c of Z at 0 subtracts (1 - max(z_c, 0)) f_c f_c^T
            for cc in range(3):
                D[cc] = 1.0 - max(w[cc], 0.0)
                for r in range(nk):
                    acc = 0.0
                    for a in range(3):
                        if lam[a] > 1e-10 * lmax:
                            ea = 0.0
                            for b in range(3):
                                ea += Ql[b, a] * G[b, r]
                            acc += Q[a, cc] * ea / np.sqrt(lam[a])
                    F[cc, r] = acc
        elif not project:
            for cc in range(3):
                for r in range(nk):
                    F[cc, r] = G[cc, r]
        # scatter the lower triangle directly
        invk = 1.0 / k
        for r in range(nk):
            jr = r // 3
            cr = r - 3 * jr
            f0 = D[0] * F[0, r]
            f1 = D[1] * F[1, r]
            f2 = D[2] * F[2, r]
            for q in range(r + 1):
                idx = hmap[i, r, q]
                if idx >= 0:
                    v = -(f0 * F[0, q] + f1 * F[1, q] + f2 * F[2, q])
                    if q - 3 * (q // 3) == cr:
                        v += (1.0 if q // 3 == jr else 0.0) - invk
                    hdata[idx] += c2 * v


def element_terms(x, elements, rest_centred, kind, ratios, passive, coef, project, want_hess, scale,
                  energy, grad, hmap, hdata):
    """Energy, gradient and (projected) Hessian of one element group, accumulated.

    Parameters
    ----------
    x : (n_v, 3) positions; elements (n, k); rest_centred (n, k, 3); kind int;
    ratios (n,) local actuation ratios; passive (n,) bool (slack cable: no energy);
    coef (n,) c_i = w_i Vol(V_i); project: 0 exact Hessian, 1 each element Hessian clamped
    to PSD; want_hess: assemble the Hessian; scale: length scale (m)
    for degeneracy thresholds.
    energy : (n,) output, c_i ||N X_i - T_i R_i^T||^2
    grad : (n_v, 3) accumulated gradient
    hmap : (n, 3k, 3k) int32 index into ``hdata`` (-1: fixed vertex or upper triangle)
    hdata : accumulated lower-triangular Hessian values (CSC order)
    """
    _terms_range(np.arange(len(elements)), 0, len(elements), x, elements, rest_centred, kind, ratios,
                 passive, coef, int(project), want_hess, scale, energy, grad, hmap, hdata)


@nb.njit(cache=True)
def dgrad_dratio(x, elements, rest_centred, kind, ratios, coef, scale, out):
    """d(grad E)/d(ratio) of one actuation group whose elements share one ratio, accumulated
    into ``out`` (n_v, 3): -2c (dT R^T + T dR^T), dR = U Omega V^T (rotation derivative)."""
    n, k = elements.shape
    X = np.empty((k, 3))
    T = np.empty((k, 3))
    dT = np.empty((k, 3))
    M = np.empty((3, 3))
    U = np.empty((3, 3))
    V = np.empty((3, 3))
    A = np.empty((3, 3))
    Q = np.empty((3, 3))
    s = np.empty(3)
    w = np.empty(3)
    R = np.empty((3, 3))
    dM = np.empty((3, 3))
    Ut = np.empty((3, 3))
    Om = np.empty((3, 3))
    dR = np.empty((3, 3))
    eps = 1e-12 * scale * scale
    for i in range(n):
        _element_frame(i, x, elements, rest_centred, kind, ratios[i], X, T, dT, M, U, s, V, A, w, Q)
        for a in range(3):
            for b in range(3):
                R[a, b] = U[a, 0] * V[b, 0] + U[a, 1] * V[b, 1] + U[a, 2] * V[b, 2]
                acc = 0.0
                for j in range(k):
                    acc += X[j, a] * dT[j, b]
                dM[a, b] = acc
        # Ut = U^T dM V
        for a in range(3):
            for b in range(3):
                acc = 0.0
                for r in range(3):
                    for c in range(3):
                        acc += U[r, a] * dM[r, c] * V[c, b]
                Ut[a, b] = acc
        for a in range(3):
            Om[a, a] = 0.0
        for p in range(3):
            a, b = _PAIRS[p]
            sab = s[a] + s[b]
            om = (Ut[a, b] - Ut[b, a]) / (sab if sab > eps else eps)
            Om[a, b] = om
            Om[b, a] = -om
        for a in range(3):
            for b in range(3):
                acc = 0.0
                for r in range(3):
                    for c in range(3):
                        acc += U[a, r] * Om[r, c] * V[b, c]
                dR[a, b] = acc
        c2 = 2.0 * coef[i]
        for j in range(k):
            v = elements[i, j]
            for a in range(3):
                acc = 0.0
                for b in range(3):
                    acc += dT[j, b] * R[a, b] + T[j, b] * dR[a, b]
                out[v, a] -= c2 * acc


def available() -> bool:
    """Whether the sparse Cholesky back end (cvxopt's CHOLMOD) is importable."""
    return _cholmod is not None


class NewtonSystem:
    """Fixed sparsity pattern, scatter maps and symbolic factorisation of the Hessian of eq. 9
    on the free coordinates of a :class:`~softkin_fk.core.forward.ForwardSolver`'s mesh.

    Parameters
    ----------
    groups : list
        The solver's element groups (``elements``, ``kind``, ``rest_centred``, ``coef``).
    n_vertices : int
    free : ndarray of int
        Free vertex indices (unknowns: 3 per free vertex, vertex-major).
    scale : float
        Typical element size (m), for degeneracy thresholds.
    """

    def __init__(self, groups, n_vertices: int, free: np.ndarray, scale: float):
        if _cholmod is None:
            raise ImportError("the Newton solver needs cvxopt (CHOLMOD); pip install cvxopt")
        self.groups = groups
        self.free = np.asarray(free)
        self.scale = float(scale)
        nf = len(self.free)
        self.n = 3 * nf
        dof = -np.ones(n_vertices, np.int64)
        dof[self.free] = np.arange(nf)
        keys = []
        per_group = []
        for g in groups:
            n, k = g.elements.shape
            d = dof[g.elements]                                            # (n, k)
            full = (3 * d[:, :, None] + np.arange(3)[None, None, :]).reshape(n, 3 * k)
            full[np.repeat(d < 0, 3, axis=1)] = -1
            li, lj = np.tril_indices(3 * k)                                # local lower triangle
            r, c = full[:, li], full[:, lj]
            keep = (r >= 0) & (c >= 0)
            # global lower triangle: the local pair (r, q) and (q, r) are one entry
            key = np.where(keep, np.minimum(r, c) * self.n + np.maximum(r, c), -1)
            per_group.append((key, keep, li, lj))
            keys.append(key[keep])
        key_all = np.unique(np.concatenate(keys))                          # CSC order: column, then row
        self.indices = (key_all % self.n).astype(np.int64)
        self.colptr = np.searchsorted(key_all // self.n, np.arange(self.n + 1)).astype(np.int64)
        self.nnz = len(key_all)
        self.maps = []
        for (key, keep, li, lj), g in zip(per_group, groups):
            n, k = g.elements.shape
            m = np.full((n, 3 * k, 3 * k), -1, np.int32)
            m[:, li, lj] = np.where(keep, np.searchsorted(key_all, key), -1)
            self.maps.append(m)
        ccol = np.repeat(np.arange(self.n), np.diff(self.colptr)).astype(np.int64)
        self._cvx = _cvx_spmatrix(_cvx_matrix(np.ones(self.nnz)), _cvx_matrix(self.indices.astype(np.int64)),
                                  _cvx_matrix(ccol), size=(self.n, self.n))
        _cholmod.options['supernodal'] = 2
        self._symbolic = _cholmod.symbolic(self._cvx, uplo='L')
        self._ccol = ccol
        self.version = 0  # counts numeric factorisations (the factor object is reused)
        #: positions of the diagonal entries in the value array
        self.diagonal = np.flatnonzero(self.indices == ccol)

    def reset(self):
        """Redo the symbolic analysis on next use (after a failed numeric factorisation)."""
        self._symbolic = None

    # ------------------------------------------------------------------------------------
    def evaluate(self, x, hessian=True, project=True):
        """Energy of eq. 9, gradient on the free coordinates (3 n_free,) and Hessian values
        (CSC lower triangle; None without ``hessian``) at positions ``x`` (n_v, 3)."""
        grad = np.zeros((len(x), 3))
        hdata = np.zeros(self.nnz) if hessian else np.zeros(1)
        E = 0.0
        for g, hm in zip(self.groups, self.maps):
            if len(g.elements) == 0:
                continue
            element_terms(x, g.elements, g.rest_centred, g.kind, g.ratios, g.passive, g.coef, project,
                          hessian, self.scale, g.energy, grad, hm, hdata)
            E += float(g.energy.sum())
        return E, grad[self.free].ravel(), (hdata if hessian else None)

    def factor(self, hdata):
        """Numeric Cholesky of the assembled Hessian (symbolic analysis reused).
        Raises ArithmeticError if it is not positive definite."""
        self.version += 1
        self._cvx.V = _cvx_matrix(hdata)
        if self._symbolic is None:
            self._symbolic = _cholmod.symbolic(self._cvx, uplo='L')
        _cholmod.numeric(self._cvx, self._symbolic)
        return self._symbolic

    def solve(self, F, rhs):
        """H^{-1} rhs for rhs of shape (3 n_free,) or (3 n_free, m)."""
        B = _cvx_matrix(np.asarray(rhs, float).reshape(self.n, -1))
        _cholmod.solve(F, B)
        return np.array(B).reshape(np.shape(rhs))

    def matrix(self, hdata) -> sp.csc_matrix:
        """Full symmetric scipy matrix (tests and diagnostics)."""
        L = sp.csc_matrix((hdata, self.indices, self.colptr), shape=(self.n, self.n))
        return (L + L.T - sp.diags(L.diagonal())).tocsc()
