"""The twin's yaw disturbance (core/yaw_disturbance.py) against analytic truth.

Truth: an Ornstein-Uhlenbeck process has stationary variance sd^2 and autocorrelation
exp(-lag / tau), whatever the step; a torque spread by mass sums to zero force and to the
torque about the COM; in the simulator, a body at rest given a torque N gains angular
momentum N t before the fluid acts (Newton's second law for rotation); off, nothing changes.
"""
import math

import numpy as np
import pytest

from frog_sim.core.simulation import DISTURBANCE_INTERVAL_S, FrogSimulation
from frog_sim.core.yaw_disturbance import YawDisturbance, torque_forces
from frog_sim.disturbance_fit import autocovariance


@pytest.mark.parametrize("h", [0.02, 0.3])
def test_ou_stationary_variance_and_autocorrelation(h):
    sd, tau = 2.0, 1.5
    ou = YawDisturbance(sd, tau, seed=4)
    x = np.array([ou.advance(h) for _ in range(200_000)])
    assert x.std() == pytest.approx(sd, rel=0.02)
    for lag in (1, 3):
        rho = np.corrcoef(x[:-lag], x[lag:])[0, 1]
        assert rho == pytest.approx(math.exp(-lag * h / tau), abs=0.01)


def test_ou_bad_values_named():
    with pytest.raises(ValueError, match="sd"):
        YawDisturbance(-1.0, 1.0)
    with pytest.raises(ValueError, match="time constant"):
        YawDisturbance(1.0, 0.0)


def test_torque_forces_are_a_pure_torque_about_the_com():
    rng = np.random.default_rng(1)
    pos = rng.normal(size=(11, 2)) * 0.03 + [0.2, -0.1]
    mass = rng.uniform(0.5, 2.0, 11) * 1e-3
    f = torque_forces(pos.ravel(), mass, 3e-4).reshape(-1, 2)
    c = mass @ pos / mass.sum()
    r = pos - c
    assert np.abs(f.sum(axis=0)).max() < 1e-12 * np.abs(f).max()
    assert float(np.sum(r[:, 0] * f[:, 1] - r[:, 1] * f[:, 0])) == pytest.approx(3e-4, rel=1e-12)
    # every node accelerates as a rigid rotation: a_i = (N / I) perp(r_i)
    inertia = float(mass @ np.sum(r ** 2, axis=1))
    assert f / mass[:, None] == pytest.approx(3e-4 / inertia * np.column_stack([-r[:, 1], r[:, 0]]), rel=1e-12)


def _angular_momentum(sim):
    x, v, m = sim.node_positions, sim.node_velocities, sim.model.mass
    c = m @ x / m.sum()
    vc = m @ v / m.sum()
    r, u = x - c, v - vc
    return float(np.sum(m * (r[:, 0] * u[:, 1] - r[:, 1] * u[:, 0])))


def test_a_held_torque_spins_the_body_up_as_newton_says():
    sim = FrogSimulation()
    sim.set_yaw_disturbance(1e-4, tau=1e9, seed=0)      # tau >> the test: the torque holds
    torque = sim.yaw_disturbance.torque
    sim.fire_limbs(["FL"], start=10.0)                  # swimming (the torque acts), the kick far later
    t = 0.04
    sim.step(int(round(t / sim.time_step)))
    # from rest the drag is second order in the tiny speeds: L = N t within a few %
    assert _angular_momentum(sim) == pytest.approx(torque * t, rel=0.05)
    assert abs(sim.rigid_body_state().yaw_rate) > 0


def test_calm_until_the_first_firing_also_after_a_reset():
    sim = FrogSimulation()
    sim.set_yaw_disturbance(1e-4, tau=1e9, seed=0)
    x0 = sim.node_positions.copy()
    sim.step(50)
    assert np.array_equal(sim.node_positions, x0)       # nothing fired: the frog stays put
    sim.execute_primitive("I")                          # no limb: still calm
    sim.step(10)
    assert np.array_equal(sim.node_positions, x0)
    sim.fire_limbs(["FL"], start=10.0)
    sim.step(20)
    assert abs(_angular_momentum(sim)) > 0
    sim.reset()
    sim.step(20)
    assert _angular_momentum(sim) == 0.0


def test_off_by_default_and_switchable():
    a, b = FrogSimulation(), FrogSimulation()
    assert a.yaw_disturbance is None
    b.set_yaw_disturbance(1e-4, 1.0, seed=2)
    b.set_yaw_disturbance(0.0, 1.0)                    # off again
    for sim in (a, b):
        sim.execute_primitive("E")
        sim.step(100)
    assert np.array_equal(a.node_positions, b.node_positions)
    assert DISTURBANCE_INTERVAL_S < 0.1


def test_autocovariance_by_hand():
    c, n = autocovariance([[1.0, 2.0, 3.0], [2.0, -1.0]], max_lag=2)
    assert n.tolist() == [5, 3, 1]
    assert c == pytest.approx([(1 + 4 + 9 + 4 + 1) / 5, (2 + 6 - 2) / 3, 3 / 1])


def test_implied_rms_by_hand():
    from frog_sim.disturbance_fit import implied_rms
    c = [4.0, 1.0, 0.5]
    assert implied_rms(c, 1) == pytest.approx(2.0)
    assert implied_rms(c, 2) == pytest.approx(math.sqrt(2 * 4.0 + 2 * 1.0))
    assert implied_rms(c, 3) == pytest.approx(math.sqrt(3 * 4.0 + 4 * 1.0 + 2 * 0.5))
    # white residuals: the error grows as sqrt(N)
    assert implied_rms([1.0, 0.0, 0.0, 0.0], 4) == pytest.approx(2.0)


def test_held_out_predictability_sees_a_state_effect_and_not_noise():
    from frog_sim.disturbance_fit import held_out_predictability
    from frog_sim.multi_period import ReplayWindow
    rng = np.random.default_rng(0)
    windows, by_state, noise = [], {}, {}
    for run in ("r1", "r2", "r3", "r4"):
        for k in range(30):
            w = ReplayWindow(run=run, index=k, time=k * 1.4, period=1.4, primitives=[rng.choice(list("BCEF"))],
                             forward=float(rng.uniform(0, 0.03)), lateral=float(rng.normal(0, 0.005)),
                             yaw_rate=float(rng.normal(0, 0.2)), real=[[0, 0, 0]])
            windows.append(w)
            by_state.setdefault(run, []).append(0.5 * w.yaw_rate + 2.0 * w.forward)
            noise.setdefault(run, []).append(float(rng.normal(0, 0.05)))
    assert held_out_predictability(windows, by_state) > 0.99
    assert held_out_predictability(windows, noise) < 0.1
