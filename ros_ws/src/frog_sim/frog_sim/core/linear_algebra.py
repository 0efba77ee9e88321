"""Sparse pattern of the Newton Jacobian and a numba banded LU solver.

The Jacobian (paper eq. 8) of the rod network is sparse: 4x4 blocks per edge,
6x6 blocks per bending triple (banded along each rod, plus the few couplings at
joint nodes). The pattern is computed once (:func:`build_jacobian_pattern`); each
element block is scattered by precomputed index maps into

* the ``data`` array of a ``scipy.sparse.csr_matrix`` (robust path, SuperLU), or
* a dense band after a reverse Cuthill-McKee renumbering of the degrees of freedom
  (fast path, :func:`band_lu_solve`, LU without pivoting, guarded by a pivot test;
  on a tiny pivot the caller falls back to SuperLU).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numba import njit
from scipy.sparse.csgraph import reverse_cuthill_mckee


@dataclass
class JacobianPattern:
    """Index maps from element blocks into CSR data and into band storage.

    Attributes
    ----------
    n : int
        Number of degrees of freedom (2N).
    indptr, indices : ndarray
        CSR structure (sorted column indices).
    edge_map_csr : ndarray of int, shape (E, 4, 4)
    bend_map_csr : ndarray of int, shape (B, 6, 6)
    diag_map_csr : ndarray of int, shape (n,)
    perm : ndarray of int, shape (n,)
        Band order -> original DOF.
    iperm : ndarray of int, shape (n,)
        Original DOF -> band order.
    bandwidth : int
        Half bandwidth (in DOFs) after renumbering.
    edge_map_band, bend_map_band, diag_map_band : ndarray of int
        Same as the CSR maps but into the flattened band array (n, 2 bw + 1).
    """

    n: int
    indptr: np.ndarray
    indices: np.ndarray
    edge_map_csr: np.ndarray
    bend_map_csr: np.ndarray
    diag_map_csr: np.ndarray
    perm: np.ndarray
    iperm: np.ndarray
    bandwidth: int
    edge_map_band: np.ndarray
    bend_map_band: np.ndarray
    diag_map_band: np.ndarray

    @property
    def nnz(self) -> int:
        """Number of structural non-zeros."""
        return int(self.indices.size)

    def csr(self, data: np.ndarray) -> sp.csr_matrix:
        """Wrap a filled ``data`` array as a CSR matrix (no copy of the structure)."""
        return sp.csr_matrix((data, self.indices, self.indptr), shape=(self.n, self.n))


def _element_dofs(nodes: np.ndarray) -> np.ndarray:
    """(M, k) node indices -> (M, 2k) DOF indices."""
    dofs = np.empty((nodes.shape[0], 2 * nodes.shape[1]), dtype=np.int64)
    dofs[:, 0::2] = 2 * nodes
    dofs[:, 1::2] = 2 * nodes + 1
    return dofs


def build_jacobian_pattern(n_nodes: int, edges: np.ndarray, bends: np.ndarray) -> JacobianPattern:
    """Precompute the CSR pattern, the RCM band order and all scatter maps.

    Parameters
    ----------
    n_nodes : int
        N.
    edges : ndarray of int, shape (E, 2)
    bends : ndarray of int, shape (B, 3)

    Returns
    -------
    JacobianPattern
    """
    n = 2 * n_nodes
    edof = _element_dofs(edges.reshape(-1, 2))
    bdof = _element_dofs(bends.reshape(-1, 3))
    rows = [np.repeat(edof, 4, axis=1).ravel(), np.repeat(bdof, 6, axis=1).ravel(), np.arange(n)]
    cols = [np.tile(edof, (1, 4)).ravel(), np.tile(bdof, (1, 6)).ravel(), np.arange(n)]
    r = np.concatenate(rows)
    c = np.concatenate(cols)
    keys = np.unique(r * n + c)
    ur, uc = keys // n, keys % n
    indptr = np.zeros(n + 1, dtype=np.int64)
    np.add.at(indptr, ur + 1, 1)
    indptr = np.cumsum(indptr)
    indices = uc.astype(np.int64)

    def to_csr(rr, cc):
        return np.searchsorted(keys, rr * n + cc).astype(np.int64)

    edge_map = to_csr(np.repeat(edof, 4, axis=1), np.tile(edof, (1, 4))).reshape(-1, 4, 4)
    bend_map = to_csr(np.repeat(bdof, 6, axis=1), np.tile(bdof, (1, 6))).reshape(-1, 6, 6)
    diag_map = to_csr(np.arange(n), np.arange(n))

    graph = sp.csr_matrix((np.ones(keys.size), indices, indptr), shape=(n, n))
    perm = np.asarray(reverse_cuthill_mckee(graph, symmetric_mode=True), dtype=np.int64)
    iperm = np.empty(n, dtype=np.int64)
    iperm[perm] = np.arange(n)
    bw = int(np.max(np.abs(iperm[ur] - iperm[uc]))) if keys.size else 0
    width = 2 * bw + 1
    csr_to_band = (iperm[ur] * width + (iperm[uc] - iperm[ur] + bw)).astype(np.int64)
    return JacobianPattern(
        n=n, indptr=indptr, indices=indices, edge_map_csr=edge_map, bend_map_csr=bend_map,
        diag_map_csr=diag_map, perm=perm, iperm=iperm, bandwidth=bw,
        edge_map_band=csr_to_band[edge_map], bend_map_band=csr_to_band[bend_map],
        diag_map_band=csr_to_band[diag_map])


@njit(cache=True)
def band_lu_solve(ab, rhs, bw, pivot_tolerance):
    """Solve ``A y = rhs`` in place for a band matrix without pivoting.

    Parameters
    ----------
    ab : ndarray, shape (n, 2 bw + 1)
        ``ab[i, j - i + bw] = A[i, j]``; overwritten by the LU factors.
    rhs : ndarray, shape (n,)
        Right-hand side, overwritten by the solution.
    bw : int
        Half bandwidth.
    pivot_tolerance : float
        A pivot with ``|p| <= pivot_tolerance * max|diag(A)|`` aborts.

    Returns
    -------
    int
        0 on success, 2 on a tiny or non-finite pivot (caller should use a pivoting solver).
    """
    n = ab.shape[0]
    scale = 0.0
    for k in range(n):
        a = abs(ab[k, bw])
        if a > scale:
            scale = a
    tiny = pivot_tolerance * scale
    for k in range(n):
        piv = ab[k, bw]
        if not (abs(piv) > tiny) or not np.isfinite(piv):
            return 2
        hi = min(n, k + bw + 1)
        for i in range(k + 1, hi):
            lik = ab[i, k - i + bw]
            if lik != 0.0:
                lik /= piv
                ab[i, k - i + bw] = lik
                for j in range(k + 1, hi):
                    ab[i, j - i + bw] -= lik * ab[k, j - k + bw]
                rhs[i] -= lik * rhs[k]
    for k in range(n - 1, -1, -1):
        s = rhs[k]
        hi = min(n, k + bw + 1)
        for j in range(k + 1, hi):
            s -= ab[k, j - k + bw] * rhs[j]
        rhs[k] = s / ab[k, bw]
    return 0
