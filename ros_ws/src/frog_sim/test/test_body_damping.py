"""The lumped rigid-body damping (core/body_damping.py) on hand-computed cases.

Truth: for a rigid motion the total force and torque are -D nu exactly; the power is
-(X_u u^2 + Y_v w^2 + N_r r^2); a pure rotation gives no force, a pure translation no
torque; in the integrator a rigid ring coasting in vacuum decays as exp(-c t / m).
"""
import numpy as np
import pytest

from frog_sim.core.body_damping import body_damping
from frog_sim.core.integrator import ImplicitEulerIntegrator
from frog_sim.core.rod_network import RodNetworkBuilder


def _cloud(n=9, seed=0):
    rng = np.random.default_rng(seed)
    pos = rng.normal(size=(n, 2)) * 0.03
    mass = rng.uniform(0.5, 2.0, n) * 1e-3
    ref = pos - mass @ pos / mass.sum()
    return pos, mass, ref


def _rigid(pos, mass, v_com, r):
    c = mass @ pos / mass.sum()
    rel = pos - c
    return (np.asarray(v_com)[None, :] + r * np.column_stack([-rel[:, 1], rel[:, 0]])).ravel()


def _totals(f, pos, mass):
    f = f.reshape(-1, 2)
    c = mass @ pos / mass.sum()
    rel = pos - c
    return f.sum(axis=0), float(np.sum(rel[:, 0] * f[:, 1] - rel[:, 1] * f[:, 0]))


@pytest.mark.parametrize("heading", [0.0, 0.7, -2.0])
def test_force_torque_and_power_of_a_rigid_motion(heading):
    pos0, mass, ref = _cloud()
    c, s = np.cos(heading), np.sin(heading)
    R = np.array([[c, -s], [s, c]])
    pos = ref @ R.T + np.array([0.1, -0.2])       # the reference turned by `heading`
    u, w, r = 0.03, -0.01, 0.4                     # body-frame surge, sway, yaw rate
    v_world = R @ np.array([u, w])
    xu, yv, nr = 0.2, 0.5, 1.5e-3
    f, power = body_damping(pos.ravel(), _rigid(pos, mass, v_world, r), mass, ref, xu, yv, nr)
    F, N = _totals(f, pos, mass)
    F_body = R.T @ F
    assert F_body == pytest.approx([-xu * u, -yv * w], rel=1e-12, abs=1e-15)
    assert N == pytest.approx(-nr * r, rel=1e-12)
    assert power == pytest.approx(-(xu * u * u + yv * w * w + nr * r * r), rel=1e-12)
    # the nodal forces do exactly that work on the nodes' velocities
    assert float(f @ _rigid(pos, mass, v_world, r)) == pytest.approx(power, rel=1e-12)


def test_pure_rotation_no_force_pure_translation_no_torque():
    pos, mass, ref = _cloud(seed=3)
    f, _ = body_damping(pos.ravel(), _rigid(pos, mass, [0.0, 0.0], 0.8), mass, ref, 0.3, 0.3, 2e-3)
    F, N = _totals(f, pos, mass)
    assert np.abs(F).max() < 1e-15 and N == pytest.approx(-2e-3 * 0.8, rel=1e-12)
    f, _ = body_damping(pos.ravel(), _rigid(pos, mass, [0.02, 0.01], 0.0), mass, ref, 0.3, 0.3, 2e-3)
    F, N = _totals(f, pos, mass)
    assert abs(N) < 1e-18 and F == pytest.approx([-0.3 * 0.02, -0.3 * 0.01], rel=1e-12)


def test_deformation_alone_is_not_damped():
    # a motion with zero linear and zero angular momentum (a "breathing" mode) feels nothing
    pos, mass, ref = _cloud(seed=5)
    c = mass @ pos / mass.sum()
    v = (pos - c) * 0.1                          # radial expansion: no momentum, no spin
    f, power = body_damping(pos.ravel(), v.ravel(), mass, ref, 0.3, 0.7, 2e-3)
    assert np.abs(f).max() < 1e-15 and abs(power) < 1e-18


def _square_ring(side=0.09, n=8):
    t = np.linspace(0, 1, n, endpoint=False)
    pts = np.concatenate([np.column_stack([t, 0 * t]), np.column_stack([1 + 0 * t, t]),
                          np.column_stack([1 - t, 1 + 0 * t]), np.column_stack([0 * t, 1 - t])]) * side
    b = RodNetworkBuilder()
    ids = b.add_nodes(pts)
    b.add_rod(ids, stretching_stiffness=1e5, bending_stiffness=1.0, linear_density=0.01, diameter=0.004,
              drag_normal=1.0, drag_tangent=0.01, closed=True)
    return b.build()


def test_integrator_decays_a_coasting_ring_exponentially():
    """No fluid, only the lumped damping: V(t) = V0 exp(-X_u t / M), r(t) = r0 exp(-N_r t / I)."""
    net = _square_ring()
    mass = np.full(net.n_nodes, 2e-3)
    xu, nr = 0.04, 2e-5
    integ = ImplicitEulerIntegrator(net, mass, fluid_density=0.0, body_damping=(xu, xu, nr))
    pos = net.positions
    c = mass @ pos / mass.sum()
    inertia = float(mass @ np.sum((pos - c) ** 2, axis=1))
    integ.set_state(v=_rigid(pos, mass, [0.03, 0.0], 0.5))
    h, steps = 1e-3, 500
    integ.advance(steps, h)
    p = integ.x.reshape(-1, 2)
    v = integ.v.reshape(-1, 2)
    V = mass @ v / mass.sum()
    rel = p - mass @ p / mass.sum()
    r = float(np.sum(mass * (rel[:, 0] * (v[:, 1] - V[1]) - rel[:, 1] * (v[:, 0] - V[0]))) / inertia)
    t = steps * h
    # explicit Euler in the damping: (1 - h c/m)^n, within O(h) of the exponential
    assert V[0] == pytest.approx(0.03 * (1 - h * xu / mass.sum()) ** steps, rel=2e-3)
    assert V[0] == pytest.approx(0.03 * np.exp(-xu * t / mass.sum()), rel=0.02)
    assert r == pytest.approx(0.5 * np.exp(-nr * t / inertia), rel=0.03)
