"""Eq. 18 and the step-5 body-frame transform against hand-computed rotations."""

import math

import numpy as np
import pytest

from frog_planner.core.prediction import apply_transition, predict_world_state
from frog_common.se2 import body_to_world, world_to_body


def test_transition_from_a_pose_facing_plus_y():
    # Facing +y (theta = 90 deg): body x is world +y, body y (left) is world -x.
    pose, vel = apply_transition([1.0, 2.0, math.pi / 2], [0.10, 0.05, 0.3, 0.02, -0.01, 0.2])
    np.testing.assert_allclose(pose, [1.0 - 0.05, 2.0 + 0.10, math.pi / 2 + 0.3], atol=1e-15)
    np.testing.assert_allclose(vel, [0.02, -0.01, 0.2])


def test_transition_from_a_pose_facing_minus_x_and_30_degrees():
    pose, _ = apply_transition([0.0, 0.0, math.pi], [0.2, 0.1, 0.0, 0, 0, 0])
    np.testing.assert_allclose(pose[:2], [-0.2, -0.1], atol=1e-15)
    c, s = math.sqrt(3) / 2, 0.5          # 30 deg by hand
    pose, _ = apply_transition([0.5, -0.5, math.radians(30)], [0.1, 0.02, -0.1, 0, 0, 0])
    np.testing.assert_allclose(pose, [0.5 + 0.1 * c - 0.02 * s, -0.5 + 0.1 * s + 0.02 * c, math.radians(30) - 0.1],
                               atol=1e-15)


def test_heading_is_wrapped():
    pose, _ = apply_transition([0.0, 0.0, 3.0], [0.0, 0.0, 0.5, 0, 0, 0])
    assert pose[2] == pytest.approx(3.5 - 2 * math.pi)


def test_broadcasting_parents_over_children():
    parents = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, math.pi / 2]])          # (2, 3)
    trans = np.array([[[0.1, 0.0, 0.0, 1, 2, 3]], [[0.0, 0.1, 0.0, 4, 5, 6]]])  # (2, 1, 6)
    children, vel = apply_transition(parents[None, :, :], trans)             # (2, 2, 3)
    assert children.shape == (2, 2, 3) and vel.shape == (2, 2, 3)
    np.testing.assert_allclose(children[0, 1], [1.0, 1.1, math.pi / 2], atol=1e-15)
    np.testing.assert_allclose(children[1, 1], [0.9, 1.0, math.pi / 2], atol=1e-15)
    np.testing.assert_allclose(vel[1, 0], [4, 5, 6])


def test_world_state_velocities_are_in_the_end_body_frame_rotated_to_world():
    # Start facing +x, turn by +90 deg; end body velocity 0.03 m/s forward = world +y.
    state = predict_world_state([0, 0, 0, 0.01, 0.0, 0.0], [0.05, 0.05, math.pi / 2, 0.03, 0.0, -0.1])
    np.testing.assert_allclose(state, [0.05, 0.05, math.pi / 2, 0.0, 0.03, -0.1], atol=1e-15)


def test_world_to_body_velocity_step5():
    # Facing +y, moving along world +y: pure forward. Moving along world -x: pure left.
    np.testing.assert_allclose(world_to_body(math.pi / 2, [0.0, 0.03]), [0.03, 0.0], atol=1e-15)
    np.testing.assert_allclose(world_to_body(math.pi / 2, [-0.02, 0.0]), [0.0, 0.02], atol=1e-15)
    # 45 deg by hand.
    h = math.sqrt(0.5)
    np.testing.assert_allclose(world_to_body(math.pi / 4, [0.01, 0.0]), [0.01 * h, -0.01 * h], atol=1e-15)
    v = np.array([[0.01, -0.02], [0.03, 0.005]])
    np.testing.assert_allclose(body_to_world([0.3, -2.0], world_to_body([0.3, -2.0], v)), v,
                               atol=1e-15)
