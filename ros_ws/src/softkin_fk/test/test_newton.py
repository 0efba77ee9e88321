"""Newton solver for eq. 9 and implicit sensitivities: independent checks.

Truths used: central finite differences of the energy and of its gradient, numpy's dense
eigen-decomposition (for the PSD projection), the local/global solver (Algorithm 1) and
central differences of forward-kinematics solves (for dx/dC).
"""
import numpy as np
import pytest

from softkin_fk.core.forward import ForwardSolver
from softkin_fk.core.models import build_dea_crawler, build_pneumatic_actuator, build_tendon_finger
from softkin_fk.core.newton import element_terms

pytest.importorskip('cvxopt')


@pytest.fixture(scope='module')
def finger():
    mesh = build_tendon_finger(resolution=1)
    return mesh, ForwardSolver(mesh)


def _state(fs, mesh, act, seed=0, noise=2e-4):
    """Positions near an actuated equilibrium (noise in m) and the solver set to its levels."""
    res = fs.solve(act, tol=1e-9)
    rng = np.random.default_rng(seed)
    x = res.positions + noise * rng.standard_normal(res.positions.shape)
    x[mesh.fixed] = mesh.vertices[mesh.fixed]
    fs._active[:] = res.active
    fs._set_levels(res.levels)
    return x


def test_gradient_and_hessian_match_finite_differences(finger):
    """Energy gradient vs central differences of E; exact Hessian-vector products vs central
    differences of the gradient (random directions, finger with two taut cables)."""
    mesh, fs = finger
    x = _state(fs, mesh, [0.95, 1.0, 0.93])
    ns = fs.newton_system()
    E, g, Hd = ns.evaluate(x, project=0)
    H = ns.matrix(Hd)
    rng = np.random.default_rng(1)
    h = 1e-7  # m
    for _ in range(3):
        v = rng.standard_normal(g.shape)
        xp, xm = x.copy(), x.copy()
        xp[ns.free] += h * v.reshape(-1, 3)
        xm[ns.free] -= h * v.reshape(-1, 3)
        Ep, gp, _ = ns.evaluate(xp, hessian=False)
        Em, gm, _ = ns.evaluate(xm, hessian=False)
        assert (Ep - Em) / (2 * h) == pytest.approx(g @ v, rel=1e-6)      # measured 4.5e-9
        hv = (gp - gm) / (2 * h)
        assert np.abs(H @ v - hv).max() < 1e-6 * np.abs(hv).max()        # measured 1.5e-9


@pytest.mark.parametrize('kind,k,ratio', [(0, 4, 1.0), (1, 3, 0.8), (2, 6, 1.3), (3, 4, 1.7)])
def test_element_hessian_projection_is_the_nearest_psd_matrix(kind, k, ratio):
    """For random (often inverted or compressed) elements the projected element Hessian equals
    numpy's eigen-decomposition of the exact one with negative eigenvalues set to zero."""
    rng = np.random.default_rng(kind)
    elements = np.arange(k)[None]
    rest = rng.normal(size=(1, k, 3))
    rest -= rest.mean(axis=1, keepdims=True)
    hmap = np.full((1, 3 * k, 3 * k), -1, np.int32)
    for r in range(3 * k):
        for q in range(r + 1):
            hmap[0, r, q] = r * 3 * k + q
    n_indefinite = 0
    for trial in range(20):
        x = rest[0] @ (np.eye(3) + 0.6 * rng.normal(size=(3, 3))).T
        mats = []
        for project in (0, 1):
            hd = np.zeros((3 * k) ** 2)
            element_terms(x, elements, rest, kind, np.array([ratio]), np.zeros(1, bool), np.ones(1), project,
                          True, 1.0, np.zeros(1), np.zeros((k, 3)), hmap, hd)
            L = np.tril(hd.reshape(3 * k, 3 * k))
            mats.append(L + L.T - np.diag(np.diag(L)))
        w, Q = np.linalg.eigh(mats[0])
        n_indefinite += w.min() < -1e-9 * w.max()
        ref = (Q * np.maximum(w, 0)) @ Q.T
        assert np.abs(mats[1] - ref).max() < 1e-9 * np.abs(ref).max()
    assert n_indefinite > 0  # the clamp was exercised


@pytest.mark.parametrize('model', ['finger', 'pneumatic', 'dea'])
def test_newton_solution_equals_local_global(model):
    """Newton and Algorithm 1 (local/global, safeguarded Anderson) reach the same shape.
    The DEA strip uses R_w = 1 in its membrane edges (Newton needs a true energy); there the
    flat equilibrium is a saddle (the exact Hessian is indefinite), so Newton runs on the
    projected Hessian alone. Tolerance 1e-7 m against deformations of 5-26 mm."""
    if model == 'finger':
        mesh, act = build_tendon_finger(1), [0.95, 0.97, 0.93]
    elif model == 'pneumatic':
        mesh, act = build_pneumatic_actuator(1, n_chambers=1, length_mm=80), [1.5]
    else:
        mesh, act = build_dea_crawler(1, membrane_shape_parameter=1.0), [1.3]
    fs = ForwardSolver(mesh)
    rn = fs.solve(act, method='newton', tol=1e-10)
    rl = fs.solve(act, method='local-global', tol=1e-10, max_iter=20000)
    assert rn.converged and rl.converged
    assert np.abs(rn.positions - mesh.vertices).max() > 4e-3
    assert np.abs(rn.positions - rl.positions).max() < 1e-7   # measured 1.3e-9 .. 6.4e-9 m
    assert rn.energy[-1] <= rl.energy[-1] * (1 + 1e-9)
    assert rn.iterations < rl.iterations


def test_newton_energy_monotone_and_default(finger):
    """Every Newton iteration lowers (never raises) eq. 9, and 'auto' picks Newton for R_w = 1."""
    mesh, fs = finger
    res = fs.solve([0.93, 0.95, 0.93], method='newton', tol=1e-9)
    e = res.energy
    assert res.converged and len(e) >= 3
    assert np.all(np.diff(e) <= 1e-13 * e[0])
    auto = fs.solve([0.93, 0.95, 0.93], tol=1e-9)
    assert auto.iterations == res.iterations
    assert np.array_equal(auto.positions, res.positions)


def test_implicit_sensitivity_matches_central_differences(finger):
    """dx/dC by the implicit function theorem vs central differences of tightly converged FK
    solves (h = 1e-4), at all vertices. At rest (s = 1, cables slack but at their target
    length) a cable gets the one-sided derivative in the pulling direction, compared with a
    one-sided difference."""
    mesh, fs = finger
    c = np.array([0.95, 0.97, 0.96])
    base = fs.solve(c, tol=1e-11)
    dx = fs.sensitivity(base)
    h = 1e-4
    for a in range(3):
        cu, cd = c.copy(), c.copy()
        cu[a] += h
        cd[a] -= h
        pu = fs.solve(cu, x0=base.positions, tol=1e-11).positions
        pd = fs.solve(cd, x0=base.positions, tol=1e-11).positions
        fd = (pu - pd) / (2 * h)
        assert np.abs(dx[:, :, a] - fd).max() < 1e-4 * np.abs(fd).max()   # measured 5e-9 .. 7e-8
    c = np.ones(3)
    base = fs.solve(c, tol=1e-11)
    assert not np.any(base.active)
    dx = fs.sensitivity(base)
    for a in range(3):
        cd = c.copy()
        cd[a] -= h
        fd = (base.positions - fs.solve(cd, x0=base.positions, tol=1e-11).positions) / h
        assert np.abs(dx[:, :, a] - fd).max() < 2e-2 * np.abs(fd).max()  # one-sided, O(h): 0.8-2.2e-4
