"""SE(2) helpers against independent computations (scipy's rotations and ODE integration)."""

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.spatial.transform import Rotation

from frog_common.se2 import (body_to_world, quaternion_yaw, relative_pose, set_yaw, twist_arc,
                             wrap_angle, world_to_body, yaw_of, yaw_quaternion)

RNG = np.random.default_rng(3)


def test_wrap_angle_range_and_equivalence():
    a = RNG.uniform(-50, 50, 1000)
    w = wrap_angle(a)
    assert np.all(w >= -np.pi) and np.all(w < np.pi)
    np.testing.assert_allclose(np.exp(1j * w), np.exp(1j * a), atol=1e-12)
    assert isinstance(wrap_angle(3 * math.pi), float) and wrap_angle(math.pi) == pytest.approx(-math.pi)


class _Q:
    x = y = z = 0.0
    w = 1.0


@pytest.mark.parametrize('yaw', [0.0, 0.3, -2.9, 3.1])
def test_quaternions_match_scipy(yaw):
    x, y, z, w = yaw_quaternion(yaw)
    np.testing.assert_allclose([x, y, z, w], Rotation.from_euler('z', yaw).as_quat(), atol=1e-12)
    q = _Q()
    set_yaw(q, yaw)
    assert yaw_of(q) == pytest.approx(yaw)
    tilted = Rotation.from_euler('ZYX', [yaw, 0.2, -0.1]).as_quat()      # yaw of a tilted body
    assert quaternion_yaw(tilted[3], *tilted[:3]) == pytest.approx(yaw)


def test_body_world_inverse_and_relative_pose_round_trip():
    h = RNG.uniform(-4, 4, 50)
    v = RNG.normal(size=(50, 2))
    np.testing.assert_allclose(world_to_body(h, body_to_world(h, v)), v, atol=1e-12)
    np.testing.assert_allclose(body_to_world(math.pi / 2, [1.0, 0.0]), [0.0, 1.0], atol=1e-12)
    p0 = np.array([0.1, -0.2, 0.7])
    d = np.array([0.03, 0.01, 0.4])
    p1 = np.concatenate([p0[:2] + body_to_world(p0[2], d[:2]), [p0[2] + d[2]]])
    np.testing.assert_allclose(relative_pose(p0, p1), d, atol=1e-12)


@pytest.mark.parametrize('twist', [(0.03, 0.0, 0.0), (0.03, 0.004, 0.5), (0.0, 0.0, -1.2), (0.02, -0.01, 1e-8)])
def test_twist_arc_is_the_integral_of_the_kinematics(twist):
    pose = np.array([0.2, -0.1, 2.5])
    u, v, r = twist

    def rhs(_, s):
        c, si = math.cos(s[2]), math.sin(s[2])
        return [c * u - si * v, si * u + c * v, r]
    ref = solve_ivp(rhs, (0.0, 1.43), pose, rtol=1e-11, atol=1e-13).y[:, -1]
    np.testing.assert_allclose(twist_arc(pose, twist, 1.43), ref, atol=1e-9)
    batch = twist_arc(np.tile(pose, (4, 1)), np.tile(twist, (4, 1)), np.array([0.0, 0.5, 1.0, 1.43]))
    np.testing.assert_allclose(batch[0], pose) and np.testing.assert_allclose(batch[3], ref, atol=1e-9)
