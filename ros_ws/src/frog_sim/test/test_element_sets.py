"""The integrator's force/energy terms as element sets (core/element_sets.py).

Truth: an independent numpy/scipy backward-Euler stepper (core/reference_numpy.py) with
the body damping of core/body_damping.py and the waterline friction of
core/waterline_friction.py added as lagged forces; a term registered
from outside the integrator (explicit: a constant nodal force, which must equal the
same ``external_force`` exactly; implicit: springs tying each node to its rest position,
whose static solution under a uniform load is the hand-computed F / k).
"""
import numpy as np

from frog_sim.core.body_damping import body_damping
from frog_sim.core.element_sets import ElementSet, ExplicitSet, element_set_maps
from frog_sim.core.extra_terms import NodalForceTerm, TetherTerm
from frog_sim.core.integrator import ImplicitEulerIntegrator
from frog_sim.core.reference_numpy import NumpyReferenceStepper
from frog_sim.core.rod_network import RodNetworkBuilder
from frog_sim.core.waterline_friction import waterline_friction

def _rod(n=6):
    b = RodNetworkBuilder()
    ids = b.add_nodes(np.column_stack([np.linspace(0.0, 0.1, n), np.zeros(n)]))
    b.add_rod(ids, stretching_stiffness=1e3, bending_stiffness=1e-4, linear_density=0.01, diameter=0.004,
              drag_normal=1.0, drag_tangent=0.01)
    return b.build()


def test_body_damping_element_matches_an_independent_numpy_stepper():
    """Frog, gait, body damping and waterline friction on: the numba step equals a numpy backward
    Euler whose applied force is body_damping() + waterline_friction() at the start of each step."""
    from frog_sim.core.actuation import ActuationLibrary
    from frog_sim.core.model_parameters import FrogParameters
    from frog_sim.core.simulation import FrogSimulation
    params = FrogParameters(yaw_damping_linear=4e-4, surge_damping_linear=0.03, sway_damping_linear=0.05,
                            waterline_friction=0.008)
    sim = FrogSimulation(params, library=ActuationLibrary.load(), force_tolerance=1e-10)
    sim.set_gait(1.0, 0.5)
    sim.set_velocity(0.02, 0.005, 0.3)
    integ = sim.integrator
    ref = NumpyReferenceStepper(integ.network, integ.mass, actuator=integ.actuator,
                                force_tolerance=integ.force_tolerance)
    system = ref._system

    def with_force(x, x_prev, v_prev, h):
        resid, jac = system(x, x_prev, v_prev, h)
        return resid - ref.f_ext, jac
    ref._system = with_force
    ref.x[:] = integ.x
    ref.v[:] = integ.v
    h = sim.time_step
    for _ in range(20):
        ref.f_ext, _ = body_damping(ref.x, ref.v, integ.mass, integ.reference, *params_coefficients(params))
        # F_c = 2 f L_o, N_c = f L_o^2 (L_o = 0.09 m)
        ref.f_ext = ref.f_ext + waterline_friction(ref.x, ref.v, integ.mass, 2 * 0.008 * 0.09, 0.008 * 0.09 ** 2)[0]
        sim.step(1)
        ref.step(h)
    scale = np.abs(integ.v).max()
    assert np.abs(ref.v - integ.v).max() < 1e-6 * scale
    assert np.abs(ref.x - integ.x).max() < 1e-9
    # and the damping did act: without it (the defaults are calibrated, not zero) the state
    # differs by much more
    undamped = params.replace(surge_damping_linear=0.0, sway_damping_linear=0.0, yaw_damping_linear=0.0,
                              waterline_friction=0.0)
    plain = FrogSimulation(undamped, library=sim.library, force_tolerance=1e-10)
    plain.set_gait(1.0, 0.5)
    plain.set_velocity(0.02, 0.005, 0.3)
    plain.step(20)
    assert np.abs(plain.integrator.v - integ.v).max() > 1e-4 * scale


def params_coefficients(params):
    return params.surge_damping_linear, params.sway_damping_linear, params.yaw_damping_linear


class _WithTerms(ImplicitEulerIntegrator):
    """An integrator with extra terms registered through the element-set hooks only."""

    extra_force = None
    spring = None

    def _explicit_sets(self):
        sets = super()._explicit_sets()
        if self.extra_force is None:
            return sets
        dofs = np.arange(self.x.size).reshape(-1, 2)
        return sets + (ExplicitSet(dofs, (NodalForceTerm(self.extra_force.reshape(-1, 2)),)),)

    def _element_sets(self):
        sets = super()._element_sets()
        if self.spring is None:
            return sets
        dofs = np.arange(self.x.size).reshape(-1, 2)
        maps = element_set_maps(self.pattern, dofs, self.fixed)
        anchor = self.network.positions.astype(float)
        stiffness = np.full(self.network.n_nodes, float(self.spring))
        return sets + (ElementSet(dofs, maps, (TetherTerm(anchor, stiffness),)),)


def test_a_registered_explicit_term_equals_the_same_external_force():
    net = _rod()
    mass = np.full(net.n_nodes, 1e-3)
    force = np.tile([0.0, -2e-3], net.n_nodes)
    a = _WithTerms(net, mass, fixed_dofs=[0, 1])
    a.extra_force = force
    b = ImplicitEulerIntegrator(net, mass, fixed_dofs=[0, 1])
    b.external_force[:] = force
    a.advance(50, 1e-3)
    b.advance(50, 1e-3)
    for _ in range(5):
        a.step(1e-3)
        b.step(1e-3)
    assert np.array_equal(a.x, b.x) and np.array_equal(a.v, b.v)
    assert np.abs(a.x - net.positions.ravel()).max() > 1e-4       # it did bend the rod
    assert np.array_equal(a.applied_force(), np.where(a.fixed, 0.0, force))


def test_a_registered_implicit_term_gives_the_hand_computed_static_solution():
    """Springs k to the rest positions, uniform load F on every node: the rod translates
    rigidly by F / k (no stretch, no bend), with either linear solver."""
    net = _rod()
    k, f = 50.0, np.array([3e-3, -1e-3])
    for solver in ('direct', 'superlu'):
        integ = _WithTerms(net, np.full(net.n_nodes, 1e-3), solver=solver)
        integ.spring = k
        integ.external_force[:] = np.tile(f, net.n_nodes)
        integ.solve_static()
        expected = (net.positions + f / k).ravel()
        assert np.abs(integ.x - expected).max() < 1e-12
        assert np.abs(integ.internal_force() + integ.external_force).max() < 1e-9   # springs carry F
