"""Local step of Algorithm 1: per-element rotations and target shapes (eq. 2-8).

For every element i with current vertices X_i (k x 3) and centred rest shape N V_i, the
local step finds the rotation R_i that best maps the (actuated) rest shape onto the current
shape and returns the centred, rotated target shape P_i = N V_i^t R_i^T (rows are vertices):

* body elements (eq. 3-5): ``P = R_w (N V) R^T + (1 - R_w) r N X`` with the
  volume-restoring factor ``r = (Vol(V) / Vol(X))^(1/3)``. (Eq. 4 as printed scales by the
  volume ratio itself; its cube root is what gives the scaled shape the rest volume, the
  stated intent of eq. 4.)
* cable triangles (eq. 6): the rest triangle (a, b, apex) shrunk by s_i along the cable
  a-b about the foot of the apex on the cable line,
* DEA prisms (eq. 7): top and bottom triangles scaled in their planes by sqrt(lambda_i)
  about their centroids, the thickness scaled by 1/lambda_i (volume preserved),
* pneumatic tetrahedra (eq. 8): the rest tetrahedron scaled by alpha_i^(1/3).

Rotations come from a reflection-safe polar decomposition of the 3x3 cross-covariance
(Jacobi eigen-decomposition of M^T M, then U = [u1, u2, u1 x u2]), so det R = +1 even for
inverted elements and flat cable triangles. The kernels are numba-compiled (``cache=True``);
:func:`local_step_numpy` is a plain numpy implementation (batched ``numpy.linalg.svd``) used
as an independent cross-check and as the baseline in the benchmarks.
"""
from __future__ import annotations

import numba as nb
import numpy as np

KIND_CODES = {'body': 0, 'cable': 1, 'dea': 2, 'pneumatic': 3}


@nb.njit(cache=True, fastmath=False, inline='always')
def jacobi_sweeps(A, Q, max_sweeps, rel_tol, scale):
    """Cyclic Jacobi rotations diagonalising a symmetric 3x3 ``A`` in place, accumulated into
    ``Q`` (the caller initialises it, usually to I); stops when the squared off-diagonal
    falls below ``rel_tol * scale**2``."""
    for sweep in range(max_sweeps):
        off = A[0, 1] * A[0, 1] + A[0, 2] * A[0, 2] + A[1, 2] * A[1, 2]
        if off <= rel_tol * scale * scale:
            break
        for pq in range(3):
            if pq == 0:
                p, q = 0, 1
            elif pq == 1:
                p, q = 0, 2
            else:
                p, q = 1, 2
            apq = A[p, q]
            if abs(apq) <= 1e-300:
                continue
            theta = (A[q, q] - A[p, p]) / (2.0 * apq)
            t = 1.0 / (abs(theta) + np.sqrt(theta * theta + 1.0))
            if theta < 0.0:
                t = -t
            c = 1.0 / np.sqrt(t * t + 1.0)
            s = t * c
            for k in range(3):
                akp = A[k, p]
                akq = A[k, q]
                A[k, p] = c * akp - s * akq
                A[k, q] = s * akp + c * akq
            for k in range(3):
                apk = A[p, k]
                aqk = A[q, k]
                A[p, k] = c * apk - s * aqk
                A[q, k] = s * apk + c * aqk
            for k in range(3):
                qkp = Q[k, p]
                qkq = Q[k, q]
                Q[k, p] = c * qkp - s * qkq
                Q[k, q] = s * qkp + c * qkq


@nb.njit(cache=True, fastmath=False, inline='always')
def _polar_rotation(M, S, V, R):
    """Rotation R (3x3, det +1) maximising trace(R^T M); S, V are 3x3 scratch arrays."""
    for a in range(3):
        for b in range(3):
            acc = 0.0
            for c in range(3):
                acc += M[c, a] * M[c, b]
            S[a, b] = acc
            V[a, b] = 1.0 if a == b else 0.0
    scale = S[0, 0] + S[1, 1] + S[2, 2]
    if scale <= 1e-300:
        for a in range(3):
            for b in range(3):
                R[a, b] = 1.0 if a == b else 0.0
        return
    jacobi_sweeps(S, V, 12, 1e-30, scale)
    # order eigenvalues descending
    i0, i1, i2 = 0, 1, 2
    if S[i0, i0] < S[i1, i1]:
        i0, i1 = i1, i0
    if S[i1, i1] < S[i2, i2]:
        i1, i2 = i2, i1
    if S[i0, i0] < S[i1, i1]:
        i0, i1 = i1, i0
    v1x, v1y, v1z = V[0, i0], V[1, i0], V[2, i0]
    v2x, v2y, v2z = V[0, i1], V[1, i1], V[2, i1]
    # u1 = M v1 / |M v1|
    u1x = M[0, 0] * v1x + M[0, 1] * v1y + M[0, 2] * v1z
    u1y = M[1, 0] * v1x + M[1, 1] * v1y + M[1, 2] * v1z
    u1z = M[2, 0] * v1x + M[2, 1] * v1y + M[2, 2] * v1z
    n1 = np.sqrt(u1x * u1x + u1y * u1y + u1z * u1z)
    u1x /= n1
    u1y /= n1
    u1z /= n1
    w2x = M[0, 0] * v2x + M[0, 1] * v2y + M[0, 2] * v2z
    w2y = M[1, 0] * v2x + M[1, 1] * v2y + M[1, 2] * v2z
    w2z = M[2, 0] * v2x + M[2, 1] * v2y + M[2, 2] * v2z
    d = u1x * w2x + u1y * w2y + u1z * w2z
    u2x = w2x - d * u1x
    u2y = w2y - d * u1y
    u2z = w2z - d * u1z
    n2 = np.sqrt(u2x * u2x + u2y * u2y + u2z * u2z)
    if n2 <= 1e-12 * n1:
        # rank-1 M: any unit vector orthogonal to u1 will do
        if abs(u1x) < 0.9:
            ex, ey, ez = 1.0, 0.0, 0.0
        else:
            ex, ey, ez = 0.0, 1.0, 0.0
        d = u1x * ex + u1y * ey + u1z * ez
        u2x, u2y, u2z = ex - d * u1x, ey - d * u1y, ez - d * u1z
        n2 = np.sqrt(u2x * u2x + u2y * u2y + u2z * u2z)
    u2x /= n2
    u2y /= n2
    u2z /= n2
    u3x = u1y * u2z - u1z * u2y
    u3y = u1z * u2x - u1x * u2z
    u3z = u1x * u2y - u1y * u2x
    v3x = v1y * v2z - v1z * v2y
    v3y = v1z * v2x - v1x * v2z
    v3z = v1x * v2y - v1y * v2x
    R[0, 0] = u1x * v1x + u2x * v2x + u3x * v3x
    R[0, 1] = u1x * v1y + u2x * v2y + u3x * v3y
    R[0, 2] = u1x * v1z + u2x * v2z + u3x * v3z
    R[1, 0] = u1y * v1x + u2y * v2x + u3y * v3x
    R[1, 1] = u1y * v1y + u2y * v2y + u3y * v3y
    R[1, 2] = u1y * v1z + u2y * v2z + u3y * v3z
    R[2, 0] = u1z * v1x + u2z * v2x + u3z * v3x
    R[2, 1] = u1z * v1y + u2z * v2y + u3z * v3y
    R[2, 2] = u1z * v1z + u2z * v2z + u3z * v3z


@nb.njit(cache=True, inline='always')
def _polar_newton(M, R):
    """Rotation factor of M by Higham's scaled Newton iteration X <- (z X + X^-T / z) / 2.

    Quadratically convergent (4-7 iterations) and cheap for well-conditioned M with
    det M > 0; returns False (R undefined) otherwise so the caller can use the Jacobi/SVD
    route, which also handles reflections (det M < 0) and rank-deficient M.
    """
    a00, a01, a02 = M[0, 0], M[0, 1], M[0, 2]
    a10, a11, a12 = M[1, 0], M[1, 1], M[1, 2]
    a20, a21, a22 = M[2, 0], M[2, 1], M[2, 2]
    nrm2 = (a00 * a00 + a01 * a01 + a02 * a02 + a10 * a10 + a11 * a11 + a12 * a12
            + a20 * a20 + a21 * a21 + a22 * a22)
    for it in range(30):
        c00 = a11 * a22 - a12 * a21
        c01 = a12 * a20 - a10 * a22
        c02 = a10 * a21 - a11 * a20
        det = a00 * c00 + a01 * c01 + a02 * c02
        if not det > 1e-6 * nrm2 * np.sqrt(nrm2):
            return False
        c10 = a02 * a21 - a01 * a22
        c11 = a00 * a22 - a02 * a20
        c12 = a01 * a20 - a00 * a21
        c20 = a01 * a12 - a02 * a11
        c21 = a02 * a10 - a00 * a12
        c22 = a00 * a11 - a01 * a10
        # X^-T = cofactor / det
        inv = 1.0 / det
        y2 = (c00 * c00 + c01 * c01 + c02 * c02 + c10 * c10 + c11 * c11 + c12 * c12
              + c20 * c20 + c21 * c21 + c22 * c22) * inv * inv
        z = (y2 / nrm2) ** 0.25
        za = 0.5 * z
        zc = 0.5 * inv / z
        b00, b01, b02 = za * a00 + zc * c00, za * a01 + zc * c01, za * a02 + zc * c02
        b10, b11, b12 = za * a10 + zc * c10, za * a11 + zc * c11, za * a12 + zc * c12
        b20, b21, b22 = za * a20 + zc * c20, za * a21 + zc * c21, za * a22 + zc * c22
        d = ((b00 - a00) ** 2 + (b01 - a01) ** 2 + (b02 - a02) ** 2 + (b10 - a10) ** 2 + (b11 - a11) ** 2
             + (b12 - a12) ** 2 + (b20 - a20) ** 2 + (b21 - a21) ** 2 + (b22 - a22) ** 2)
        a00, a01, a02, a10, a11, a12, a20, a21, a22 = b00, b01, b02, b10, b11, b12, b20, b21, b22
        nrm2 = (a00 * a00 + a01 * a01 + a02 * a02 + a10 * a10 + a11 * a11 + a12 * a12
                + a20 * a20 + a21 * a21 + a22 * a22)
        if d <= 1e-26 * nrm2:
            R[0, 0], R[0, 1], R[0, 2] = a00, a01, a02
            R[1, 0], R[1, 1], R[1, 2] = a10, a11, a12
            R[2, 0], R[2, 1], R[2, 2] = a20, a21, a22
            return True
    return False


@nb.njit(cache=True, inline='always')
def _rotation(M, S, V, R):
    """Proper rotation maximising trace(R^T M): scaled Newton when M is well conditioned with
    det M > 0, else the reflection-safe Jacobi/SVD route."""
    if not _polar_newton(M, R):
        _polar_rotation(M, S, V, R)


@nb.njit(cache=True)
def polar_rotations(M):
    """Reflection-safe rotations of a batch of 3x3 matrices.

    Parameters
    ----------
    M : ndarray, shape (n, 3, 3)

    Returns
    -------
    R : ndarray, shape (n, 3, 3)
        Proper rotations maximising trace(R^T M) (the rotation factor of the polar
        decomposition, with the smallest singular direction flipped if det M < 0).
    """
    n = M.shape[0]
    R = np.empty((n, 3, 3))
    S = np.empty((3, 3))
    V = np.empty((3, 3))
    for i in range(n):
        _rotation(M[i], S, V, R[i])
    return R


@nb.njit(cache=True, inline='always')
def _tet_volume(P, i0, i1, i2, i3):
    ax = P[i1, 0] - P[i0, 0]
    ay = P[i1, 1] - P[i0, 1]
    az = P[i1, 2] - P[i0, 2]
    bx = P[i2, 0] - P[i0, 0]
    by = P[i2, 1] - P[i0, 1]
    bz = P[i2, 2] - P[i0, 2]
    cx = P[i3, 0] - P[i0, 0]
    cy = P[i3, 1] - P[i0, 1]
    cz = P[i3, 2] - P[i0, 2]
    return ((ay * bz - az * by) * cx + (az * bx - ax * bz) * cy + (ax * by - ay * bx) * cz) / 6.0


@nb.njit(cache=True, inline='always')
def _element_volume(P, k):
    """Signed volume of a tet (k=4); unsigned volume of a prism (k=6); 0 for triangles."""
    if k == 4:
        return _tet_volume(P, 0, 1, 2, 3)
    if k == 6:
        return abs(_tet_volume(P, 3, 4, 5, 0)) + abs(_tet_volume(P, 4, 5, 0, 1)) + abs(_tet_volume(P, 5, 0, 1, 2))
    return 0.0


@nb.njit(cache=True, inline='always')
def actuated_shape(i, rest_centred, kind, ratio, T, dT):
    """Centred actuated rest shape T of element i (eq. 6-8) and dT/dratio (for the Newton step)."""
    k = rest_centred.shape[1]
    for j in range(k):
        for c in range(3):
            T[j, c] = rest_centred[i, j, c]
            dT[j, c] = 0.0
    if kind == 1:
        ux = T[1, 0] - T[0, 0]
        uy = T[1, 1] - T[0, 1]
        uz = T[1, 2] - T[0, 2]
        ln = np.sqrt(ux * ux + uy * uy + uz * uz)
        ux /= ln
        uy /= ln
        uz /= ln
        t = (T[2, 0] - T[0, 0]) * ux + (T[2, 1] - T[0, 1]) * uy + (T[2, 2] - T[0, 2]) * uz
        f0 = T[0, 0] + t * ux
        f1 = T[0, 1] + t * uy
        f2 = T[0, 2] + t * uz
        for j in range(2):
            dT[j, 0] = T[j, 0] - f0
            dT[j, 1] = T[j, 1] - f1
            dT[j, 2] = T[j, 2] - f2
            T[j, 0] = f0 + ratio * dT[j, 0]
            T[j, 1] = f1 + ratio * dT[j, 1]
            T[j, 2] = f2 + ratio * dT[j, 2]
    elif kind == 2:
        sl = np.sqrt(ratio)
        for tri in range(2):
            o = 3 * tri
            g0 = (T[o, 0] + T[o + 1, 0] + T[o + 2, 0]) / 3.0
            g1 = (T[o, 1] + T[o + 1, 1] + T[o + 2, 1]) / 3.0
            g2 = (T[o, 2] + T[o + 1, 2] + T[o + 2, 2]) / 3.0
            for j in range(o, o + 3):
                for c in range(3):
                    g = g0 if c == 0 else (g1 if c == 1 else g2)
                    rel = T[j, c] - g
                    T[j, c] = g / ratio + sl * rel
                    dT[j, c] = -g / (ratio * ratio) + 0.5 / sl * rel
    elif kind == 3:
        a = ratio ** (1.0 / 3.0)
        da = a / (3.0 * ratio)
        for j in range(k):
            for c in range(3):
                dT[j, c] = da * T[j, c]
                T[j, c] *= a
    if kind != 0:
        for c in range(3):
            m = 0.0
            md = 0.0
            for j in range(k):
                m += T[j, c]
                md += dT[j, c]
            m /= k
            md /= k
            for j in range(k):
                T[j, c] -= m
                dT[j, c] -= md


@nb.njit(cache=True, inline='always')
def _element_target(i, x, elements, rest_centred, kind, ratios, passive, shape_parameter,
                    rest_volume, coef, targets, energy, X, T, dT, M, S, V, R):
    k = elements.shape[1]
    cx = 0.0
    cy = 0.0
    cz = 0.0
    for j in range(k):
        v = elements[i, j]
        X[j, 0] = x[v, 0]
        X[j, 1] = x[v, 1]
        X[j, 2] = x[v, 2]
        cx += X[j, 0]
        cy += X[j, 1]
        cz += X[j, 2]
    cx /= k
    cy /= k
    cz /= k
    for j in range(k):
        X[j, 0] -= cx
        X[j, 1] -= cy
        X[j, 2] -= cz
    if kind != 0 and passive[i]:
        for j in range(k):
            for c in range(3):
                targets[i, j, c] = X[j, c]
        energy[i] = 0.0
        return
    # reference shape to rotate (actuated rest shape), centred
    actuated_shape(i, rest_centred, kind, ratios[i], T, dT)
    # cross-covariance M = X^T T, rotation R maximises tr(R^T M): X ~ T R^T
    for a in range(3):
        for b in range(3):
            acc = 0.0
            for j in range(k):
                acc += X[j, a] * T[j, b]
            M[a, b] = acc
    _rotation(M, S, V, R)
    rw = 1.0
    r = 1.0
    if kind == 0:
        rw = shape_parameter[i]
        if rw < 1.0:
            vol = _element_volume(X, k)
            rv = rest_volume[i]
            if k == 4:
                vol = abs(vol)
                rv = abs(rv)
            if vol < 1e-3 * rv:
                vol = 1e-3 * rv
            r = (rv / vol) ** (1.0 / 3.0)  # eq. 4 (volume-restoring scale)
    e = 0.0
    for j in range(k):
        for a in range(3):
            rot = R[a, 0] * T[j, 0] + R[a, 1] * T[j, 1] + R[a, 2] * T[j, 2]
            p = rw * rot + (1.0 - rw) * r * X[j, a]  # eq. 5 blend
            targets[i, j, a] = p
            d = X[j, a] - p
            e += d * d
    energy[i] = coef[i] * e


@nb.njit(cache=True)
def _target_scratch(k):
    """Scratch of :func:`_element_target` for elements of ``k`` vertices: X, T, dT (k, 3); M, S, V, R (3, 3)."""
    return (np.empty((k, 3)), np.empty((k, 3)), np.empty((k, 3)), np.empty((3, 3)), np.empty((3, 3)),
            np.empty((3, 3)), np.empty((3, 3)))


@nb.njit(parallel=True)  # not cached: numba cannot cache this parallel kernel
def _local_targets_parallel(x, elements, rest_centred, kind, ratios, passive, shape_parameter,
                            rest_volume, coef, targets, energy):
    n, k = elements.shape
    nth = nb.get_num_threads()
    chunk = (n + nth - 1) // nth
    for t in nb.prange(nth):
        X, T, dT, M, S, V, R = _target_scratch(k)     # one set per thread
        for i in range(t * chunk, min(n, (t + 1) * chunk)):
            _element_target(i, x, elements, rest_centred, kind, ratios, passive, shape_parameter,
                            rest_volume, coef, targets, energy, X, T, dT, M, S, V, R)


@nb.njit(cache=True)
def _local_targets_serial(x, elements, rest_centred, kind, ratios, passive, shape_parameter,
                          rest_volume, coef, targets, energy):
    n, k = elements.shape
    X, T, dT, M, S, V, R = _target_scratch(k)
    for i in range(n):
        _element_target(i, x, elements, rest_centred, kind, ratios, passive, shape_parameter,
                        rest_volume, coef, targets, energy, X, T, dT, M, S, V, R)


#: groups with at least this many elements use the multi-threaded kernel
PARALLEL_THRESHOLD = 20000


def local_targets(x, elements, rest_centred, kind, ratios, passive, shape_parameter,
                  rest_volume, coef, targets, energy):
    """Local step for one element group (Algorithm 1, lines 4-5).

    Parameters
    ----------
    x : ndarray, shape (n_v, 3)
        Current vertex positions (m).
    elements : ndarray of int, shape (n, k)
    rest_centred : ndarray, shape (n, k, 3)
        N V_i: rest shapes with their centroid at the origin (m).
    kind : int
        0 body, 1 cable, 2 DEA, 3 pneumatic.
    ratios : ndarray, shape (n,)
        Local actuation ratios s_i, lambda_i or alpha_i (ignored for body elements).
    passive : ndarray of bool, shape (n,)
        True where an actuation element exerts nothing (a slack cable): target = current.
    shape_parameter : ndarray, shape (n,)
        R_w per element (body elements, eq. 5).
    rest_volume : ndarray, shape (n,)
        Signed rest volume (tets) or volume (prisms), m^3.
    coef : ndarray, shape (n,)
        w_i Vol(V_i) of eq. 9.
    targets : ndarray, shape (n, k, 3)
        Output: centred, rotated target shapes P_i (m).
    energy : ndarray, shape (n,)
        Output: coef_i ||N X_i - P_i||_F^2 at the current positions (eq. 9 terms).
    """
    f = _local_targets_parallel if len(elements) >= PARALLEL_THRESHOLD else _local_targets_serial
    f(x, elements, rest_centred, kind, ratios, passive, shape_parameter, rest_volume, coef, targets, energy)


@nb.njit(cache=True)
def scatter_rhs(elements, coef, targets, rhs):
    """Accumulate sum_i coef_i S_i^T P_i into ``rhs`` (n_v, 3) (right side of eq. 10)."""
    n, k = elements.shape
    for i in range(n):
        c = coef[i]
        for j in range(k):
            v = elements[i, j]
            rhs[v, 0] += c * targets[i, j, 0]
            rhs[v, 1] += c * targets[i, j, 1]
            rhs[v, 2] += c * targets[i, j, 2]


@nb.njit(cache=True)
def element_measure_ratios(x, elements, kind, rest_measure):
    """Current-to-rest ratio of each actuation element's driven measure.

    Cable: length of edge a-b; DEA: mean area of the two triangles; pneumatic: volume.
    (Serial: actuator groups are small, and a thread launch per call cost ~10 ms on a busy
    2-core machine, more than the work.)

    Returns
    -------
    ndarray, shape (n,)
    """
    n = elements.shape[0]
    out = np.empty(n)
    P = np.empty((4, 3))
    for i in range(n):
        e = elements[i]
        if kind == 1:
            dx = x[e[1], 0] - x[e[0], 0]
            dy = x[e[1], 1] - x[e[0], 1]
            dz = x[e[1], 2] - x[e[0], 2]
            m = np.sqrt(dx * dx + dy * dy + dz * dz)
        elif kind == 2:
            m = 0.0
            for o in (0, 3):
                ax = x[e[o + 1], 0] - x[e[o], 0]
                ay = x[e[o + 1], 1] - x[e[o], 1]
                az = x[e[o + 1], 2] - x[e[o], 2]
                bx = x[e[o + 2], 0] - x[e[o], 0]
                by = x[e[o + 2], 1] - x[e[o], 1]
                bz = x[e[o + 2], 2] - x[e[o], 2]
                qx = ay * bz - az * by
                qy = az * bx - ax * bz
                qz = ax * by - ay * bx
                m += 0.25 * np.sqrt(qx * qx + qy * qy + qz * qz)
        else:
            for j in range(4):
                for c in range(3):
                    P[j, c] = x[e[j], c]
            m = _tet_volume(P, 0, 1, 2, 3)
        out[i] = m / rest_measure[i]
    return out


def rest_measures(x: np.ndarray, elements: np.ndarray, kind: str) -> np.ndarray:
    """Rest value of each actuation element's driven measure (cable length l_i in m, DEA
    mean triangle area a_i in m^2, pneumatic signed volume u_i in m^3), shape (n,)."""
    return element_measure_ratios(x, elements, KIND_CODES[kind], np.ones(len(elements)))


def least_norm_ratios(current_ratio: np.ndarray, rest_measure: np.ndarray, target_total: float) -> np.ndarray:
    """Local ratios closest to the current ones that meet an actuator constraint (eq. 6-8).

    Solves ``min ||r - current_ratio||`` subject to ``sum_i r_i m_i = target_total``
    (the least-norm correction of Sec. II-D).

    Parameters
    ----------
    current_ratio : ndarray, shape (n,)
        Current-to-rest ratio of each element's measure.
    rest_measure : ndarray, shape (n,)
        Rest measures m_i (l_i, a_i or u_i).
    target_total : float
        Required total (s L - L_R, lambda A or alpha U).

    Returns
    -------
    ndarray, shape (n,)
    """
    gap = target_total - float(current_ratio @ rest_measure)
    return current_ratio + rest_measure * (gap / float(rest_measure @ rest_measure))


# --- plain numpy reference ------------------------------------------------------------------
def local_step_numpy(x, elements, rest_centred, kind, ratios, passive, shape_parameter,
                     rest_volume, coef):
    """Same contract as :func:`local_targets` in plain numpy (batched SVD); returns
    ``(targets, energy)``. Used as an independent cross-check and benchmark baseline."""
    X = x[elements]
    X = X - X.mean(axis=1, keepdims=True)
    T = rest_centred.copy()
    n, k = elements.shape
    if kind == 1:
        a, b, c = T[:, 0], T[:, 1], T[:, 2]
        u = (b - a) / np.linalg.norm(b - a, axis=1, keepdims=True)
        f = a + np.einsum('ij,ij->i', c - a, u)[:, None] * u
        T[:, :2] = f[:, None] + ratios[:, None, None] * (T[:, :2] - f[:, None])
    elif kind == 2:
        for o in (0, 3):
            g = T[:, o:o + 3].mean(axis=1, keepdims=True)
            T[:, o:o + 3] = g / ratios[:, None, None] + np.sqrt(ratios)[:, None, None] * (T[:, o:o + 3] - g)
    elif kind == 3:
        T = T * np.cbrt(ratios)[:, None, None]
    if kind != 0:
        T = T - T.mean(axis=1, keepdims=True)
    M = np.einsum('nja,njb->nab', X, T)
    U, _, Vt = np.linalg.svd(M)
    D = np.ones((n, 3))
    D[:, 2] = np.sign(np.linalg.det(U @ Vt))
    D[D[:, 2] == 0, 2] = 1.0
    R = np.einsum('nab,nb,nbc->nac', U, D, Vt)
    rot = np.einsum('nab,njb->nja', R, T)
    if kind == 0:
        rw = shape_parameter[:, None, None]
        if k == 4:
            a_, b_, c_, d_ = X[:, 0], X[:, 1], X[:, 2], X[:, 3]
            vol = np.abs(np.einsum('ij,ij->i', np.cross(b_ - a_, c_ - a_), d_ - a_) / 6.0)
        else:
            idx = [[3, 4, 5, 0], [4, 5, 0, 1], [5, 0, 1, 2]]
            vol = 0.0
            for q in idx:
                a_, b_, c_, d_ = (X[:, j] for j in q)
                vol = vol + np.abs(np.einsum('ij,ij->i', np.cross(b_ - a_, c_ - a_), d_ - a_) / 6.0)
        rv = np.abs(rest_volume)
        r = np.cbrt(rv / np.maximum(vol, 1e-3 * rv))[:, None, None]
        P = rw * rot + (1 - rw) * r * X
    else:
        P = np.where(passive[:, None, None], X, rot)
    energy = coef * ((X - P) ** 2).sum(axis=(1, 2))
    return P, energy
