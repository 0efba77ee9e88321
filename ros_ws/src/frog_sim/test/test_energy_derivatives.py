"""Analytic gradients and Hessians of the elastic energies vs central finite differences."""
import numpy as np
import pytest

from frog_sim.core.elastic_energy import network_energy_gradient, network_hessian
from frog_sim.core.rod_network import RodNetworkBuilder, discrete_curvature


def _joint_network(seed=0):
    """A closed 6-node loop with two rods hanging from joint nodes, randomly perturbed."""
    rng = np.random.default_rng(seed)
    b = RodNetworkBuilder()
    ang = np.linspace(0, 2 * np.pi, 7)[:-1]
    ring = b.add_nodes(np.column_stack([0.02 * np.cos(ang), 0.02 * np.sin(ang)]))
    b.add_rod(ring, stretching_stiffness=50.0, bending_stiffness=2e-4, linear_density=0.1,
              diameter=0.01, drag_normal=0.8, drag_tangent=0.008, closed=True)
    for corner in (0, 3):
        p0 = b._pos[corner]
        d = np.array(p0) / np.linalg.norm(p0)
        limb = b.add_nodes([np.array(p0) + 0.004 * k * d for k in range(1, 5)])
        chain = [corner, *limb]
        b.add_rod(chain, stretching_stiffness=30.0, bending_stiffness=4e-5, linear_density=0.01,
                  diameter=0.004, drag_normal=1.0, drag_tangent=0.01, natural_curvature=80.0)
        # joint bend coupling the ring edge to the limb's first edge
        b.add_bend(ring[(corner - 1) % 6], corner, limb[0], bending_stiffness=3e-5)
    net = b.build()
    x = net.positions.ravel() + 4e-4 * rng.standard_normal(net.n_dof)
    return net, x


def _fd_gradient(net, x, h):
    g = np.zeros_like(x)
    for k in range(x.size):
        xp, xm = x.copy(), x.copy()
        xp[k] += h
        xm[k] -= h
        g[k] = (network_energy_gradient(net, xp)[0] - network_energy_gradient(net, xm)[0]) / (2 * h)
    return g


def _fd_hessian(net, x, h):
    hess = np.zeros((x.size, x.size))
    for k in range(x.size):
        xp, xm = x.copy(), x.copy()
        xp[k] += h
        xm[k] -= h
        hess[:, k] = (network_energy_gradient(net, xp)[1] - network_energy_gradient(net, xm)[1]) / (2 * h)
    return hess


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_gradient_matches_central_differences_including_joints(seed):
    net, x = _joint_network(seed)
    _, g = network_energy_gradient(net, x)
    g_fd = _fd_gradient(net, x, 1e-7)
    assert np.linalg.norm(g - g_fd) / np.linalg.norm(g) < 1e-6
    # joint nodes (0 and 3) are in three bends: check their rows separately
    for node in (0, 3):
        sl = slice(2 * node, 2 * node + 2)
        assert np.linalg.norm(g[sl] - g_fd[sl]) / np.linalg.norm(g[sl]) < 1e-6


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_hessian_matches_central_differences_including_joints(seed):
    net, x = _joint_network(seed)
    hess = network_hessian(net, x)
    h_fd = _fd_hessian(net, x, 1e-7)
    assert np.allclose(hess, hess.T, rtol=0, atol=1e-9 * np.abs(hess).max())
    assert np.linalg.norm(hess - h_fd) / np.linalg.norm(hess) < 1e-6
    for node in (0, 3):
        rows = slice(2 * node, 2 * node + 2)
        assert np.linalg.norm(hess[rows] - h_fd[rows]) / np.linalg.norm(hess[rows]) < 1e-6


def test_bending_energy_matches_definition():
    """E_b = EI (kappa - kappa0)^2 dl / 2 with kappa = 2 tan(phi/2)/dl, phi by atan2."""
    net, x = _joint_network(5)
    stretch_free = net
    stretch_free.edge_stretching_stiffness[:] = 0.0
    energy, _ = network_energy_gradient(stretch_free, x)
    kappa = discrete_curvature(x.reshape(-1, 2), net.bends, net.bend_length)
    expected = np.sum(0.5 * net.bend_stiffness * (kappa - net.bend_natural_curvature) ** 2 * net.bend_length)
    assert energy == pytest.approx(expected, rel=1e-12)


def test_drag_jacobian_matches_central_differences():
    """Drag force derivatives w.r.t. node velocities and positions (used by Newton, eq. 8)."""
    from frog_sim.core.fluid import drag_element
    rng = np.random.default_rng(4)
    for _ in range(5):
        xs = rng.normal(size=4) * 0.004
        vs = rng.normal(size=4) * 0.05
        cn, ct = 0.3, 0.004
        f = np.empty(4)
        jv = np.empty((4, 4))
        jx = np.empty((4, 4))
        drag_element(*xs, *vs, cn, ct, f, jv, jx)
        jv_fd = np.empty((4, 4))
        jx_fd = np.empty((4, 4))
        fp, fm = np.empty(4), np.empty(4)
        dummy = np.empty((4, 4))
        for k in range(4):
            for arr, out, hstep in ((vs, jv_fd, 1e-7), (xs, jx_fd, 1e-9)):
                plus, minus = arr.copy(), arr.copy()
                plus[k] += hstep
                minus[k] -= hstep
                if arr is vs:
                    drag_element(*xs, *plus, cn, ct, fp, dummy, dummy.copy())
                    drag_element(*xs, *minus, cn, ct, fm, dummy, dummy.copy())
                else:
                    drag_element(*plus, *vs, cn, ct, fp, dummy, dummy.copy())
                    drag_element(*minus, *vs, cn, ct, fm, dummy, dummy.copy())
                out[:, k] = (fp - fm) / (2 * hstep)
        assert np.linalg.norm(jv - jv_fd) / np.linalg.norm(jv) < 1e-6
        assert np.linalg.norm(jx - jx_fd) / np.linalg.norm(jx) < 1e-6
