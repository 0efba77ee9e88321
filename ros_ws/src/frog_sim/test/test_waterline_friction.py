"""The waterline friction (core/waterline_friction.py) on hand-computed cases.

Truth: for a rigid motion the total force is -F_c tanh(|V| / v_s) V / |V| and the torque
about the centre of mass -N_c tanh(r / r_s), whatever the nodes' layout; the nodal forces
do exactly the power F . V + N r <= 0; in the integrator a rigid ring spinning or gliding in
vacuum loses speed at the constant rate N_c / I (F_c / M) and stops at r_0 I / N_c.
"""
import numpy as np
import pytest

from frog_sim.core.integrator import ImplicitEulerIntegrator
from frog_sim.core.rod_network import RodNetworkBuilder
from frog_sim.core.waterline_friction import SPEED_SCALE, YAW_RATE_SCALE, waterline_friction


def _cloud(n=9, seed=0):
    rng = np.random.default_rng(seed)
    pos = rng.normal(size=(n, 2)) * 0.03
    mass = rng.uniform(0.5, 2.0, n) * 1e-3
    return pos, mass, pos - mass @ pos / mass.sum()


def _rigid(pos, mass, v_com, r):
    rel = pos - mass @ pos / mass.sum()
    return (np.asarray(v_com)[None, :] + r * np.column_stack([-rel[:, 1], rel[:, 0]])).ravel()


def _totals(f, pos, mass):
    f = f.reshape(-1, 2)
    rel = pos - mass @ pos / mass.sum()
    return f.sum(axis=0), float(np.sum(rel[:, 0] * f[:, 1] - rel[:, 1] * f[:, 0]))


def _square_ring(side=0.09, n=8):
    t = np.linspace(0, 1, n, endpoint=False)
    pts = np.concatenate([np.column_stack([t, 0 * t]), np.column_stack([1 + 0 * t, t]),
                          np.column_stack([1 - t, 1 + 0 * t]), np.column_stack([0 * t, 1 - t])]) * side
    b = RodNetworkBuilder()
    ids = b.add_nodes(pts)
    b.add_rod(ids, stretching_stiffness=1e5, bending_stiffness=1.0, linear_density=0.01, diameter=0.004,
              drag_normal=1.0, drag_tangent=0.01, closed=True)
    return b.build()


@pytest.mark.parametrize("v_com, r", [((0.03, -0.01), 0.4), ((-0.002, 0.0005), -0.05), ((0.0, 0.0), 0.003)])
def test_force_torque_and_power_of_a_rigid_motion(v_com, r):
    pos, mass, _ = _cloud(seed=2)
    fc, nc = 3e-4, 6e-5
    v = _rigid(pos, mass, v_com, r)
    f, power = waterline_friction(pos.ravel(), v, mass, fc, nc)
    F, N = _totals(f, pos, mass)
    speed = float(np.hypot(*v_com))
    F_true = (-fc * np.tanh(speed / SPEED_SCALE) * np.asarray(v_com) / speed) if speed > 0 else np.zeros(2)
    N_true = -nc * np.tanh(r / YAW_RATE_SCALE)
    assert F == pytest.approx(F_true, rel=1e-12, abs=1e-18)
    assert N == pytest.approx(N_true, rel=1e-12)
    assert power == pytest.approx(float(F_true @ np.asarray(v_com)) + N_true * r, rel=1e-12, abs=1e-20)
    assert power <= 0.0
    assert float(f @ v) == pytest.approx(power, rel=1e-12, abs=1e-20)


def test_well_above_the_regularisation_it_is_coulomb_friction():
    # 30 mm/s and 0.5 rad/s: tanh(30), tanh(50) = 1 to 1e-25: the full F_c and N_c
    pos, mass, _ = _cloud(seed=4)
    f, _ = waterline_friction(pos.ravel(), _rigid(pos, mass, [0.0, 0.03], 0.5), mass, 2e-4, 5e-5)
    F, N = _totals(f, pos, mass)
    assert F == pytest.approx([0.0, -2e-4], abs=1e-16)
    assert N == pytest.approx(-5e-5, rel=1e-12)


def test_at_rest_and_for_a_deformation_alone_nothing():
    pos, mass, _ = _cloud(seed=5)
    f, power = waterline_friction(pos.ravel(), np.zeros(pos.size), mass, 3e-4, 6e-5)
    assert np.abs(f).max() == 0.0 and power == 0.0
    c = mass @ pos / mass.sum()
    f, power = waterline_friction(pos.ravel(), ((pos - c) * 0.1).ravel(), mass, 3e-4, 6e-5)
    assert np.abs(f).max() < 1e-15 and abs(power) < 1e-18


def _ring_motion(integ, mass):
    p = integ.x.reshape(-1, 2)
    v = integ.v.reshape(-1, 2)
    V = mass @ v / mass.sum()
    rel = p - mass @ p / mass.sum()
    inertia = float(mass @ np.sum(rel ** 2, axis=1))
    return V, float(np.sum(mass * (rel[:, 0] * (v[:, 1] - V[1]) - rel[:, 1] * (v[:, 0] - V[0]))) / inertia)


def test_integrator_brakes_a_spinning_and_gliding_ring_at_a_constant_rate_and_stops_it():
    """No fluid, only the friction: r(t) = r0 - N_c t / I, V(t) = V0 - F_c t / M, then rest."""
    net = _square_ring()
    mass = np.full(net.n_nodes, 2e-3)
    fc, nc = 6e-4, 2e-5
    integ = ImplicitEulerIntegrator(net, mass, fluid_density=0.0, waterline_friction=(fc, nc))
    pos = net.positions
    c = mass @ pos / mass.sum()
    inertia = float(mass @ np.sum((pos - c) ** 2, axis=1))
    M = mass.sum()
    integ.set_state(v=_rigid(pos, mass, [0.03, 0.0], 0.5))
    h = 1e-3
    integ.advance(200, h)
    V, r = _ring_motion(integ, mass)
    assert r == pytest.approx(0.5 - nc * 0.2 / inertia, rel=1e-3)
    assert V[0] == pytest.approx(0.03 - fc * 0.2 / M, rel=1e-3) and abs(V[1]) < 1e-9
    # stops: the ring's speed falls to zero within the hand-computed stopping times (plus a few
    # regularisation times) and stays there, no reversal
    t_stop = max(0.5 * inertia / nc, 0.03 * M / fc)
    integ.advance(int(1.2 * t_stop / h) + 200, h)
    V, r = _ring_motion(integ, mass)
    assert abs(r) < 1e-3 * 0.5 and np.hypot(*V) < 1e-3 * 0.03
