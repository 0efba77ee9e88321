"""Forward kinematics (Algorithm 1): invariants and independent references."""
import numpy as np
import pytest

from softkin_fk.core.forward import ForwardSolver
from softkin_fk.core.local_step import local_step_numpy, local_targets, polar_rotations
from softkin_fk.core.mesh import ElementGroup, SoftMesh, tet_volumes
from softkin_fk.core.meshing import voxel_tets
from softkin_fk.core.models import build_tendon_finger, build_two_material_bar

H = 2.5e-3  # bar cell size (m)


def bar(shape_parameter=1.0, n=(24, 4, 4)):
    """60 x 10 x 10 mm bar; base face (x = 0) and end face are both handles."""
    v, t, _, g = voxel_tets(np.ones(n, bool), H)
    base, end = g[0].ravel(), g[-1].ravel()
    mesh = SoftMesh(v, [ElementGroup('body', 'body', t, shape_parameter=shape_parameter)],
                    fixed=np.r_[base, end])
    return mesh, end


def rot_z(deg):
    th = np.deg2rad(deg)
    return np.array([[np.cos(th), -np.sin(th), 0], [np.sin(th), np.cos(th), 0], [0, 0, 1]])


def bent_handles(mesh, end, deg=30.0, shift=(-0.005, 0.01, 0.0)):
    fp = mesh.vertices[mesh.fixed].copy()
    m = np.isin(mesh.fixed, end)
    c = mesh.vertices[end].mean(axis=0)
    fp[m] = (mesh.vertices[mesh.fixed[m]] - c) @ rot_z(deg).T + c + np.asarray(shift)
    return fp


def test_polar_rotations_match_svd_and_are_proper():
    rng = np.random.default_rng(1)
    M = rng.normal(size=(2000, 3, 3))          # about half have det < 0 (reflections)
    M[:5, :, 2] = 0.0                          # rank-2 (flat triangles)
    M[5:8] = np.outer([1.0, 2.0, 3.0], [0.5, -1.0, 2.0])  # rank 1
    R = polar_rotations(M)
    assert np.allclose(np.linalg.det(R), 1.0, atol=1e-12)
    assert np.allclose(np.einsum('nji,njk->nik', R, R), np.eye(3), atol=1e-12)
    U, _, Vt = np.linalg.svd(M[8:])
    D = np.ones((len(U), 3))
    D[:, 2] = np.sign(np.linalg.det(U @ Vt))
    ref = np.einsum('nab,nb,nbc->nac', U, D, Vt)
    assert np.abs(R[8:] - ref).max() < 1e-9
    # optimality for the degenerate ones: trace(R^T M) equals the SVD bound
    s = np.linalg.svd(M[:8], compute_uv=False)
    bound = s[:, 0] + s[:, 1] + np.sign(np.linalg.det(M[:8])) * s[:, 2]
    assert np.allclose(np.einsum('nij,nij->n', R[:8], M[:8]), bound, atol=1e-9)


@pytest.mark.parametrize('kind,k', [(0, 4), (1, 3), (2, 6), (3, 4)])
def test_numba_local_step_matches_numpy_reference(kind, k):
    rng = np.random.default_rng(kind)
    n = 50
    x = rng.normal(size=(n * k, 3))
    elements = np.arange(n * k).reshape(n, k)
    rest = rng.normal(size=(n, k, 3))
    rest -= rest.mean(axis=1, keepdims=True)
    ratios = rng.uniform(0.7, 1.3, n)
    passive = rng.uniform(size=n) < 0.2
    rw = rng.uniform(0, 1, n)
    rvol = rng.uniform(0.5, 2.0, n)
    coef = rng.uniform(0.5, 2.0, n)
    tg = np.zeros((n, k, 3))
    en = np.zeros(n)
    local_targets(x, elements, rest, kind, ratios, passive, rw, rvol, coef, tg, en)
    P, E = local_step_numpy(x, elements, rest, kind, ratios, passive, rw, rvol, coef)
    assert np.abs(tg - P).max() < 1e-9
    assert np.allclose(en, E, rtol=1e-9, atol=1e-12)


def test_body_targets_rigid_and_volume_preserving_limits():
    """R_w = 1 target is congruent to the rest tet; R_w = 0 target has the rest volume (eq. 3-5)."""
    rng = np.random.default_rng(2)
    rest = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float) * 1e-3
    F = np.eye(3) + 0.3 * rng.normal(size=(3, 3))
    if np.linalg.det(F) < 0:
        F[:, 0] *= -1
    x = rest @ F.T
    rc = (rest - rest.mean(axis=0))[None]
    vol0 = tet_volumes(rest, np.array([[0, 1, 2, 3]]))
    for rw, check in ((1.0, 'shape'), (0.0, 'volume')):
        tg = np.zeros((1, 4, 3))
        local_targets(x, np.array([[0, 1, 2, 3]]), rc, 0, np.ones(1), np.zeros(1, bool), np.array([rw]),
                      vol0, np.ones(1), tg, np.zeros(1))
        if check == 'shape':
            d_t = np.linalg.norm(tg[0][:, None] - tg[0][None], axis=2)
            d_r = np.linalg.norm(rest[:, None] - rest[None], axis=2)
            assert np.allclose(d_t, d_r, atol=1e-15)
        else:
            assert tet_volumes(tg[0], np.array([[0, 1, 2, 3]]))[0] == pytest.approx(vol0[0], rel=1e-12)


def test_zero_actuation_returns_rest_shape():
    finger = build_tendon_finger(resolution=1)
    res = ForwardSolver(finger).solve()
    assert res.converged
    assert np.abs(res.positions - finger.vertices).max() < 1e-12


def test_rigid_motion_equivariance():
    """Moving the whole problem rigidly moves the deformed shape by the same motion."""
    mesh, end = bar()
    fp = bent_handles(mesh, end)
    res = ForwardSolver(mesh).solve(fixed_positions=fp, tol=1e-11, max_iter=5000)
    R = rot_z(40.0) @ np.array([[1, 0, 0], [0, np.cos(0.7), -np.sin(0.7)], [0, np.sin(0.7), np.cos(0.7)]])
    t = np.array([0.3, -0.2, 0.5])
    moved = mesh.transformed(R, t)
    res2 = ForwardSolver(moved).solve(fixed_positions=fp @ R.T + t, tol=1e-11, max_iter=5000)
    assert res.converged and res2.converged
    assert np.abs(res2.positions - (res.positions @ R.T + t)).max() < 1e-8  # m (deformation ~1e-2 m)


@pytest.mark.parametrize('method,accelerate', [('local-global', False), ('local-global', True), ('lbfgs', True),
                                               ('newton', True)])
def test_energy_never_increases(method, accelerate):
    mesh, end = bar()
    res = ForwardSolver(mesh).solve(fixed_positions=bent_handles(mesh, end), method=method,
                                    accelerate=accelerate, safeguard='energy', tol=1e-9, max_iter=3000)
    e = res.energy
    assert res.converged
    assert len(e) > 5
    assert np.all(np.diff(e) <= 1e-13 * e[0])


@pytest.mark.slow
def test_agrees_with_libigl_arap():
    """Pure body elements (R_w = 1) with handles vs libigl's ARAP (per-element energy).

    The two discretise ARAP differently (vertex shape matching of eq. 2 vs cotangent-weighted
    edges), so they agree to a few per cent of the handle displacement, not to round-off:
    tolerance max 6 %, RMS 3 % (measured 3.9 % and 1.9 %).
    """
    igl = pytest.importorskip('igl')
    mesh, end = bar()
    fp = bent_handles(mesh, end)
    ours = ForwardSolver(mesh).solve(fixed_positions=fp, tol=1e-10, max_iter=5000).positions
    data = igl.ARAPData()
    data.max_iter = 2000
    igl.arap_precomputation(mesh.vertices, mesh.tets, 3, mesh.fixed.astype(np.int32), data)
    ref = igl.arap_solve(fp, data, mesh.vertices.copy())
    dev = np.linalg.norm(ref - ours, axis=1)
    disp = np.linalg.norm(ref - mesh.vertices, axis=1).max()
    assert dev.max() < 0.06 * disp
    assert np.sqrt(np.mean(dev ** 2)) < 0.03 * disp


def test_soft_limit_preserves_volume_rigid_limit_does_not():
    """Stretching a bar by 20 %: R_w -> 0 keeps the volume, R_w = 1 (shape keeping) does not."""
    ratios = {}
    for rw in (0.02, 0.2, 1.0):
        mesh, end = bar(rw)
        fp = mesh.vertices[mesh.fixed].copy()
        fp[np.isin(mesh.fixed, end), 0] += 0.012
        res = ForwardSolver(mesh).solve(fixed_positions=fp, tol=1e-9, max_iter=5000)
        assert res.converged
        t = mesh.tets
        ratios[rw] = tet_volumes(res.positions, t).sum() / tet_volumes(mesh.vertices, t).sum()
    assert abs(ratios[0.02] - 1) < 0.01
    assert abs(ratios[0.02] - 1) < abs(ratios[0.2] - 1) < abs(ratios[1.0] - 1)
    assert ratios[1.0] > 1.1


def test_rigid_material_keeps_shape_next_to_soft():
    """Two-material bar: the R_w = 1 part strains far less than the R_w = 0.05 part."""
    m = build_two_material_bar(50.0, 1.0, 0.05)
    fp = m.vertices[m.fixed].copy()
    fp[np.isin(m.fixed, m.info['end_vertices']), 0] += 0.01
    res = ForwardSolver(m).solve(fixed_positions=fp, tol=1e-9, max_iter=5000)
    iface = m.info['interface_vertices']
    d1 = (res.positions[iface, 0] - m.vertices[iface, 0]).mean()
    strain_a = d1 / m.info['interface_m']
    strain_b = (0.01 - d1) / (m.info['length_m'] - m.info['interface_m'])
    assert strain_b > 5 * strain_a > 0


def test_bad_inputs_raise_clear_errors():
    finger = build_tendon_finger(resolution=1)
    fs = ForwardSolver(finger)
    with pytest.raises(ValueError, match='expected 3'):
        fs.solve([0.9, 1.0])
    with pytest.raises(ValueError, match='outside its bounds'):
        fs.solve([0.1, 1.0, 1.0])
    with pytest.raises(ValueError, match='resolution'):
        build_tendon_finger(resolution=0)
    v, t, _, _ = voxel_tets(np.ones((2, 1, 1), bool), H)
    with pytest.raises(ValueError, match='fixed vertex'):
        ForwardSolver(SoftMesh(v, [ElementGroup('body', 'body', t)]))
