"""Global step of Algorithm 1: the normal equations of eq. 10, factorised once.

Setting dE/dv_j = 0 in eq. 9 with the targets P_i fixed gives, per coordinate,

    A x = b,   A = sum_i c_i S_i^T N_i S_i,   b = sum_i c_i S_i^T P_i,

with c_i = w_i Vol(V_i), S_i the vertex selector of element i and N_i = I - 1/k 11^T
(N^T N = N, and P_i is already centred). A depends only on the rest mesh and the weights, so
it is factorised once (Algorithm 1, line 2) and the factor is reused for the x, y and z
columns in every iteration. Fixed vertices are eliminated: A_ff x_f = b_f - A_fc x_c.

Back ends: ``cholespy`` (sparse Cholesky; optional, used when importable) or scipy's
SuperLU (always available).
"""
from __future__ import annotations

from typing import List, Optional

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

try:  # optional, faster back-substitution (see ROS_ON_PIP.md)
    import cholespy as _cholespy
except ImportError:  # pragma: no cover - depends on the environment
    _cholespy = None


def assemble_system_matrix(n_vertices: int, element_blocks: List[tuple]) -> sp.csr_matrix:
    """Assemble A = sum_i c_i S_i^T N_i S_i.

    Parameters
    ----------
    n_vertices : int
    element_blocks : list of (elements, coef)
        ``elements`` (n, k) int and ``coef`` (n,) = w_i Vol(V_i).

    Returns
    -------
    scipy.sparse.csr_matrix, shape (n_vertices, n_vertices)
        Symmetric positive semi-definite (its null space is the constant vector).
    """
    rows, cols, vals = [], [], []
    for elements, coef in element_blocks:
        n, k = elements.shape
        if n == 0:
            continue
        N = np.eye(k) - 1.0 / k
        r = np.repeat(elements, k, axis=1).ravel()
        c = np.tile(elements, (1, k)).ravel()
        v = (coef[:, None, None] * N[None]).ravel()
        rows.append(r)
        cols.append(c)
        vals.append(v)
    A = sp.coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                      shape=(n_vertices, n_vertices))
    return A.tocsr()


class GlobalSolver:
    """Pre-factorised solve of eq. 10 with fixed vertices eliminated.

    Parameters
    ----------
    A : scipy.sparse matrix, shape (n_v, n_v)
        System matrix from :func:`assemble_system_matrix`.
    fixed : ndarray of int, shape (n_f,)
        Fixed vertex indices. Every connected part of the mesh needs at least one, otherwise
        the reduced matrix is singular (rigid translation).
    backend : {'auto', 'cholespy', 'superlu'}
        Factorisation back end; 'auto' takes cholespy when it is installed.

    Raises
    ------
    ValueError
        If no vertex is fixed or the factorisation fails (a floating part).
    """

    def __init__(self, A: sp.spmatrix, fixed: np.ndarray, backend: str = 'auto'):
        n = A.shape[0]
        fixed = np.asarray(fixed, np.int64)
        if fixed.size == 0:
            raise ValueError("no fixed vertices: the global step needs at least one fixed vertex "
                             "per connected part (rigid translation is otherwise free)")
        is_free = np.ones(n, bool)
        is_free[fixed] = False
        self.free = np.flatnonzero(is_free)
        self.fixed = fixed
        A = sp.csr_matrix(A)
        self.A = A
        self.A_ff = A[self.free][:, self.free].tocsc()
        self.A_fc = A[self.free][:, fixed].tocsr()
        if backend == 'auto':
            backend = 'cholespy' if _cholespy is not None else 'superlu'
        if backend == 'cholespy' and _cholespy is None:
            raise ValueError("backend 'cholespy' requested but the cholespy package is not installed")
        if backend not in ('cholespy', 'superlu'):
            raise ValueError(f"unknown backend {backend!r}; expected 'auto', 'cholespy' or 'superlu'")
        self.backend = backend
        if backend == 'cholespy':
            coo = self.A_ff.tocoo()
            self._chol = _cholespy.CholeskySolverD(len(self.free), coo.row.astype(np.int32),
                                                   coo.col.astype(np.int32), coo.data,
                                                   _cholespy.MatrixType.COO)
        else:
            try:
                self._lu = spla.splu(self.A_ff, permc_spec='MMD_AT_PLUS_A',
                                     options={'SymmetricMode': True})
            except RuntimeError as exc:
                raise ValueError(f"global matrix is singular ({exc}); does every connected part "
                                 "of the mesh have a fixed vertex?") from exc

    def solve(self, rhs: np.ndarray, fixed_positions: np.ndarray, out: Optional[np.ndarray] = None) -> np.ndarray:
        """Solve for all vertex positions.

        Parameters
        ----------
        rhs : ndarray, shape (n_v, 3)
            b of eq. 10.
        fixed_positions : ndarray, shape (n_f, 3)
            Positions of the fixed vertices (m).
        out : ndarray, shape (n_v, 3), optional
            Written in place and returned.

        Returns
        -------
        ndarray, shape (n_v, 3)
        """
        b = rhs[self.free] - self.A_fc @ fixed_positions
        if self.backend == 'cholespy':
            xf = np.empty_like(b)
            self._chol.solve(np.ascontiguousarray(b), xf)
        else:
            xf = self._lu.solve(np.asfortranarray(b))
        if out is None:
            out = np.empty_like(rhs)
        out[self.free] = xf
        out[self.fixed] = fixed_positions
        return out

    def solve_free(self, r: np.ndarray) -> np.ndarray:
        """A_ff^{-1} r for a right side on the free vertices, shape (n_free, 3)."""
        if self.backend == 'cholespy':
            out = np.empty_like(r)
            self._chol.solve(np.ascontiguousarray(r), out)
            return out
        return self._lu.solve(np.asfortranarray(r))

    def residual(self, x: np.ndarray, rhs: np.ndarray) -> np.ndarray:
        """(A x - b) on the free vertices, shape (n_free, 3): half the energy gradient."""
        return (self.A @ x - rhs)[self.free]
