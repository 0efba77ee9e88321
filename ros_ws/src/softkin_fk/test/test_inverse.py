"""Inverse kinematics (Algorithm 2) on the 3-tendon finger."""
import numpy as np
import pytest

from softkin_fk.core.forward import ForwardSolver
from softkin_fk.core.inverse import solve_ik
from softkin_fk.core.models import build_tendon_finger


@pytest.fixture(scope='module')
def finger():
    mesh = build_tendon_finger(resolution=1)
    return mesh, ForwardSolver(mesh)


@pytest.mark.parametrize('direction,jacobian', [('gradient', 'central'), ('gauss-newton', 'central'),
                                                ('gradient', 'implicit'), ('gauss-newton', 'implicit')])
def test_ik_reaches_fk_generated_target(finger, direction, jacobian):
    """A target produced by FK from a known actuation is reached within lambda = 0.2 mm, with
    the paper's central-difference Jacobian and with the implicit (IFT) one."""
    mesh, fs = finger
    known = np.array([0.95, 0.97, 0.93])
    target = fs.solve(known, tol=1e-10).marker(mesh)
    res = solve_ik(fs, target, direction=direction, jacobian=jacobian)
    assert res.success and not res.out_of_reach
    assert res.error <= 0.2e-3
    assert np.linalg.norm(res.reached[0] - target) <= 0.2e-3
    lo = np.array([a.bounds[0] for a in mesh.actuators])
    assert np.all(res.actuation >= lo) and np.all(res.actuation <= 1.0)
    # the returned error is the distance of an independent FK of the returned actuation
    check = fs.solve(res.actuation, tol=1e-10).marker(mesh)
    assert np.linalg.norm(check - target) <= 0.25e-3


def test_out_of_reach_reports_nearest_reachable_point(finger):
    """A target beyond the straight finger's tip cannot be reached: IK says so and returns
    the closest point it can reach, which no sampled configuration beats."""
    mesh, fs = finger
    target = np.array([0.150, 0.020, 0.0125])
    res = solve_ik(fs, target, direction='gauss-newton')
    assert res.out_of_reach and not res.success
    assert res.error == pytest.approx(np.linalg.norm(res.reached[0] - target))
    rng = np.random.default_rng(0)
    lo = np.array([a.bounds[0] for a in mesh.actuators])
    for _ in range(4):
        c = rng.uniform(lo, 1.0)
        p = fs.solve(c, tol=1e-7).marker(mesh)
        assert np.linalg.norm(p - target) >= res.error - 1e-6


def test_ik_rejects_bad_input(finger):
    mesh, fs = finger
    with pytest.raises(ValueError, match='unknown marker'):
        solve_ik(fs, [0.1, 0.05, 0.0125], markers=('nose',))
    with pytest.raises(ValueError, match='expected'):
        solve_ik(fs, [0.1, 0.05])
    with pytest.raises(ValueError, match='tau'):
        solve_ik(fs, [0.1, 0.05, 0.0125], tau=1.5)
    with pytest.raises(ValueError, match='jacobian'):
        solve_ik(fs, [0.1, 0.05, 0.0125], jacobian='forward')
