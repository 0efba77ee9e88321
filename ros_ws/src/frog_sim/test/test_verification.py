"""Verification of the DER core against closed-form and independent references."""
import numpy as np
import pytest
from scipy.integrate import solve_bvp

from frog_sim.core.fluid import drag_forces, drag_prefactors, lumped_masses
from frog_sim.core.frog_model import build_frog_model
from frog_sim.core.integrator import ImplicitEulerIntegrator
from frog_sim.core.model_parameters import FrogParameters
from frog_sim.core.rod_network import RodNetworkBuilder, straight_rod

E_LIMB = 3.0e6
R_LIMB = 0.002
I_LIMB = np.pi * R_LIMB ** 4 / 4
A_LIMB = np.pi * R_LIMB ** 2
EI = E_LIMB * I_LIMB
EA = E_LIMB * A_LIMB


def _cantilever(length, n_free_edges, ea=EA):
    """Clamped rod: nodes 0 and 1 straddle the wall (s = -dl/2, +dl/2), tip at s = L.

    The wall sits at the mid-point of the clamped edge, so the bending elements sample
    the moment at the mid-points of [0, L] (second-order accurate clamp).
    """
    dl = length / (n_free_edges + 0.5)
    s = (np.arange(n_free_edges + 2) - 0.5) * dl
    b = RodNetworkBuilder()
    ids = b.add_nodes(np.column_stack([s, np.zeros_like(s)]))
    b.add_rod(ids, stretching_stiffness=ea, bending_stiffness=EI, linear_density=0.01,
              diameter=0.004, drag_normal=1.0, drag_tangent=0.01)
    net = b.build()
    integ = ImplicitEulerIntegrator(net, lumped_masses(net, 0.0, 0.0), fluid_density=0.0,
                                    fixed_dofs=[0, 1, 2, 3], force_tolerance=1e-13)
    return net, integ


def test_cantilever_small_tip_load_matches_beam_theory_at_default_resolution():
    params = FrogParameters()
    length = params.limb_length
    n = int(round(length / params.edge_length - 0.5))   # default dl ~ 3.9 mm
    net, integ = _cantilever(length, n)
    deflection = 1e-3 * length
    load = 3 * EI * deflection / length ** 3
    integ.external_force[-1] = -load
    integ.solve_static()
    tip = integ.x.reshape(-1, 2)[-1]
    expected = load * length ** 3 / (3 * EI)            # P L^3 / (3 EI)
    assert abs(-tip[1] - expected) / expected < 0.01


def _elastica_tip(load, length):
    """Independent reference: inextensible elastica with a dead tip load (solve_bvp)."""
    k = load / EI

    def rhs(s, y):  # y = theta, theta', x, y
        return np.vstack([y[1], k * np.cos(y[0]), np.cos(y[0]), np.sin(y[0])])

    def bc(ya, yb):
        return np.array([ya[0], yb[1], ya[2], ya[3]])

    s = np.linspace(0, length, 200)
    guess = np.zeros((4, s.size))
    guess[2] = s
    sol = solve_bvp(rhs, bc, s, guess, tol=1e-10, max_nodes=100000)
    assert sol.success
    return sol.sol(length)[2], sol.sol(length)[3]


def test_large_deflection_matches_elastica():
    length = 0.035
    load = 3.0 * EI / length ** 2                       # P L^2 / EI = 3: tip drops ~ 0.6 L
    x_ref, y_ref = _elastica_tip(load, length)
    net, integ = _cantilever(length, 30, ea=1e3 * EA)
    integ.external_force[-1] = -load
    integ.solve_static(load_steps=10)
    tip = integ.x.reshape(-1, 2)[-1]
    deflection_ref = np.hypot(length - x_ref, y_ref)
    assert y_ref < -0.4 * length                         # really large deflection
    assert np.hypot(tip[0] - x_ref, tip[1] - y_ref) / deflection_ref < 0.02


def test_free_rod_with_natural_curvature_relaxes_to_circle():
    length, n = 0.1, 50
    kappa0 = np.pi / length                              # half circle
    net = straight_rod(n, length, stretching_stiffness=EA, bending_stiffness=EI,
                       natural_curvature=kappa0)
    integ = ImplicitEulerIntegrator(net, lumped_masses(net, 0.0, 0.0), fluid_density=0.0,
                                    fixed_dofs=[0, 1, 3], force_tolerance=1e-13)
    target = integ.kappa0.copy()
    for k in range(1, 11):                               # continuation in kappa0
        integ.kappa0[:] = target * k / 10
        integ.solve_static()
    pts = integ.x.reshape(-1, 2)
    # algebraic (Kasa) circle fit: x^2 + y^2 + a x + b y + c = 0
    mat = np.column_stack([pts[:, 0], pts[:, 1], np.ones(len(pts))])
    a, b, c = np.linalg.lstsq(mat, -(pts ** 2).sum(axis=1), rcond=None)[0]
    radius = np.sqrt(a * a / 4 + b * b / 4 - c)
    residual = np.abs(np.hypot(pts[:, 0] + a / 2, pts[:, 1] + b / 2) - radius).max()
    assert residual < 1e-3 * radius                      # it is a circle
    assert abs(radius * kappa0 - 1.0) < 0.005             # of radius 1 / kappa0


def _free_frog_integrator(h_seed=0):
    model = build_frog_model(FrogParameters())
    integ = ImplicitEulerIntegrator(model.network, model.mass, fluid_density=0.0,
                                    force_tolerance=1e-12)
    rng = np.random.default_rng(h_seed)
    # random node velocities: the network deforms, so stretching and bending forces act
    integ.set_state(v=0.005 * rng.standard_normal(integ.v.size))
    return model, integ


def test_momentum_without_drag():
    """Linear momentum is conserved to round-off; angular momentum obeys backward Euler's
    exact balance L_{k+1} - L_k = h sum m v_{k+1} x v_k (internal forces exert no torque)."""
    model, integ = _free_frog_integrator()
    m = model.mass
    h = 1e-3
    p0 = (m[:, None] * integ.v.reshape(-1, 2)).sum(axis=0)

    def ang(x, v):
        x = x.reshape(-1, 2)
        v = v.reshape(-1, 2)
        return np.sum(m * (x[:, 0] * v[:, 1] - x[:, 1] * v[:, 0]))

    l0 = ang(integ.x, integ.v)
    predicted = 0.0
    scale_p = np.sum(m * np.linalg.norm(integ.v.reshape(-1, 2), axis=1))
    for _ in range(1000):                                # 1 s
        v_old = integ.v.reshape(-1, 2).copy()
        integ.step(h)
        v_new = integ.v.reshape(-1, 2)
        predicted += h * np.sum(m * (v_new[:, 0] * v_old[:, 1] - v_new[:, 1] * v_old[:, 0]))
    p1 = (m[:, None] * integ.v.reshape(-1, 2)).sum(axis=0)
    l1 = ang(integ.x, integ.v)
    assert integ.stats.halvings == 0          # the balance below is per full step
    assert np.linalg.norm(p1 - p0) < 1e-10 * scale_p
    scale_l = np.sum(m * np.linalg.norm(integ.x.reshape(-1, 2), axis=1)
                     * np.linalg.norm(integ.v.reshape(-1, 2), axis=1))
    assert abs((l1 - l0) - predicted) < 1e-9 * scale_l


def test_forces_are_frame_invariant():
    model, integ = _free_frog_integrator(3)
    rng = np.random.default_rng(7)
    x = integ.x + 2e-4 * rng.standard_normal(integ.x.size)
    v = 0.05 * rng.standard_normal(integ.x.size)
    f = integ.internal_force(x)
    cn, ct = drag_prefactors(model.network, 1000.0)
    fd = np.zeros_like(x)
    drag_forces(x, v, model.network.edges, cn, ct, fd)
    angle = 0.7
    rot = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    shift = np.array([0.3, -1.2])
    xr = (x.reshape(-1, 2) @ rot.T + shift).ravel()
    vr = (v.reshape(-1, 2) @ rot.T).ravel()
    fr = integ.internal_force(xr)
    fdr = np.zeros_like(x)
    drag_forces(xr, vr, model.network.edges, cn, ct, fdr)
    expected = (f.reshape(-1, 2) @ rot.T).ravel()
    assert np.abs(fr - expected).max() < 1e-7 * np.abs(f).max()
    assert np.abs(fdr - (fd.reshape(-1, 2) @ rot.T).ravel()).max() < 1e-12 * np.abs(fd).max()
    assert np.abs(f.reshape(-1, 2).sum(axis=0)).max() < 1e-9 * np.abs(f).max()   # no net force


@pytest.mark.parametrize('direction', ['normal', 'tangent'])
def test_terminal_velocity_quadratic_drag(direction):
    length, n, diameter, rho = 0.1, 20, 0.004, 1000.0
    cn_coef, ct_coef = 1.0, 0.01
    net = straight_rod(n, length, stretching_stiffness=EA, bending_stiffness=EI,
                       linear_density=1250 * A_LIMB, diameter=diameter,
                       drag_normal=cn_coef, drag_tangent=ct_coef)
    mass = lumped_masses(net, rho, 1.0)
    integ = ImplicitEulerIntegrator(net, mass, fluid_density=rho, force_tolerance=1e-14)
    total = 1e-3
    weight = np.zeros(net.n_nodes)                      # drag length of each node
    np.add.at(weight, net.edges[:, 0], 0.5 * net.edge_rest_length)
    np.add.at(weight, net.edges[:, 1], 0.5 * net.edge_rest_length)
    axis = 1 if direction == 'normal' else 0
    integ.external_force.reshape(-1, 2)[:, axis] = total * weight / length
    # the steady state of backward Euler is the exact terminal velocity for any step,
    # so large steps reach it quickly (time constant m / (k v_t) ~ 2 s for the tangent case)
    integ.advance(600, 0.05)
    coef = cn_coef if direction == 'normal' else ct_coef
    expected = np.sqrt(2 * total / (rho * coef * diameter * length))
    v = integ.v.reshape(-1, 2)[:, axis]
    assert np.abs(v / expected - 1).max() < 0.01


@pytest.mark.parametrize("damping, friction", [((0.0, 0.0, 0.0), 0.0), ((0.03, 0.08, 4e-4), 0.0),
                                              ((0.03, 0.08, 4e-4), 0.008)])
def test_numpy_reference_step_matches_numba_step(damping, friction):
    """The benchmark's numpy/scipy baseline computes the same backward-Euler steps, with and
    without the lumped body damping and the waterline friction (each written twice: numba
    kernel, vectorised numpy)."""
    from frog_sim.core.actuation import ActuationLibrary
    from frog_sim.core.reference_numpy import NumpyReferenceStepper
    from frog_sim.core.simulation import FrogSimulation
    params = FrogParameters().replace(surge_damping_linear=damping[0], sway_damping_linear=damping[1],
                                      yaw_damping_linear=damping[2], waterline_friction=friction)
    sim = FrogSimulation(params, library=ActuationLibrary.load(), force_tolerance=1e-10)
    sim.set_gait(1.0, 0.5)
    sim.set_pose(0.0, 0.0, 0.6)             # surge and sway differ from x and y
    sim.set_velocity(0.02, 0.005, 0.1)
    integ = sim.integrator
    ref = NumpyReferenceStepper(integ.network, integ.mass, actuator=integ.actuator,
                                force_tolerance=integ.force_tolerance, body_damping=damping,
                                reference=integ.reference,
                                waterline_friction=(2 * friction * 0.09, friction * 0.09 ** 2))
    ref.x[:] = integ.x
    ref.v[:] = integ.v
    h = sim.time_step
    for _ in range(20):                      # through the start of the power stroke
        sim.step(1)
        ref.step(h)
    scale = np.abs(integ.v).max()
    assert np.abs(ref.v - integ.v).max() < 1e-6 * scale
    assert np.abs(ref.x - integ.x).max() < 1e-9


def test_failed_step_raises_clear_error_and_keeps_state():
    """A step that cannot converge even after halving raises ConvergenceError (no NaN state)."""
    from frog_sim.core.integrator import ConvergenceError
    net = straight_rod(10, 0.035, stretching_stiffness=EA, bending_stiffness=EI)
    integ = ImplicitEulerIntegrator(net, lumped_masses(net, 1000.0, 1.0), max_iterations=1,
                                    max_halvings=2, force_tolerance=1e-15)
    integ.kappa0[:] = 150.0                   # far from equilibrium: needs many iterations
    x_before = integ.x.copy()
    with pytest.raises(ConvergenceError, match=r't = 0 s with h = .* after 2 halvings'):
        integ.step(1e-3)
    assert np.array_equal(integ.x, x_before) and integ.time == 0.0
    with pytest.raises(ValueError, match='time step h'):
        integ.step(float('nan'))
