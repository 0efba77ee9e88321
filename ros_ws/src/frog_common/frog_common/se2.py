"""Planar rigid-body geometry (SE(2)) every frog package uses, REP-103 frames (x forward, z up).

A pose is (x [m], y [m], heading [rad]) in the world frame; a body twist is (forward [m/s],
lateral [m/s], yaw rate [rad/s]) in the body frame. Functions take arrays of any leading shape.
Quaternion helpers work on anything with ``x, y, z, w`` attributes (a geometry_msgs
Quaternion) without importing ROS.
"""

from __future__ import annotations

import math

import numpy as np


def wrap_angle(angle):
    """Angles wrapped to [-pi, pi), any shape (a scalar comes back as a float)."""
    wrapped = (np.asarray(angle, dtype=float) + np.pi) % (2.0 * np.pi) - np.pi
    return float(wrapped) if wrapped.ndim == 0 else wrapped


def yaw_of(q) -> float:
    """Yaw [rad] of a quaternion message (rotation about z; ZYX convention)."""
    return quaternion_yaw(q.w, q.x, q.y, q.z)


def quaternion_yaw(w: float, x: float, y: float, z: float) -> float:
    """Yaw [rad] of a unit quaternion given as w, x, y, z (ZYX convention)."""
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def yaw_quaternion(yaw: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a rotation by ``yaw`` about z: the field order of geometry_msgs."""
    return 0.0, 0.0, math.sin(yaw / 2.0), math.cos(yaw / 2.0)


def set_yaw(q, yaw: float) -> None:
    """Set a quaternion message to a rotation by ``yaw`` about z."""
    q.x, q.y, q.z, q.w = yaw_quaternion(yaw)


def world_to_body(heading, vector):
    """World-frame planar vectors (..., 2) in the body frame of ``heading``: R(-theta) v."""
    th = np.asarray(heading, dtype=float)
    v = np.asarray(vector, dtype=float)
    c, s = np.cos(th), np.sin(th)
    return np.stack([c * v[..., 0] + s * v[..., 1], -s * v[..., 0] + c * v[..., 1]], axis=-1)


def body_to_world(heading, vector):
    """Body-frame planar vectors (..., 2) in the world frame: R(theta) v."""
    th = np.asarray(heading, dtype=float)
    v = np.asarray(vector, dtype=float)
    c, s = np.cos(th), np.sin(th)
    return np.stack([c * v[..., 0] - s * v[..., 1], s * v[..., 0] + c * v[..., 1]], axis=-1)


def relative_pose(p0, p1) -> np.ndarray:
    """Pose ``p1`` in the body frame of ``p0``: (dx, dy) and the heading change (not wrapped)."""
    p0 = np.asarray(p0, dtype=float)
    p1 = np.asarray(p1, dtype=float)
    d = world_to_body(p0[..., 2], p1[..., :2] - p0[..., :2])
    return np.concatenate([d, (p1[..., 2] - p0[..., 2])[..., None]], axis=-1)


def twist_arc(pose, twist, dt) -> np.ndarray:
    """Pose after moving for ``dt`` [s] at a constant body twist: a circular arc, exactly.

    The body turns by r*dt while it moves with (u, v) in its own frame; the displacement is
    the integral of R(r t) (u, v) over [0, dt]. The heading is left continuous (not wrapped).
    ``pose`` (..., 3), ``twist`` (..., 3), ``dt`` a scalar or (...,).
    """
    p = np.asarray(pose, dtype=float)
    v = np.asarray(twist, dtype=float)
    dt = np.asarray(dt, dtype=float)
    if p.ndim == 1 and v.ndim == 1 and dt.ndim == 0:
        return _twist_arc_one(*p.tolist(), *v.tolist(), float(dt))
    a = v[..., 2] * dt
    small = np.abs(a) < 1e-6
    a_safe = np.where(small, 1.0, a)
    # (1/dt) integral_0^dt R(r t) dt = [[sin a / a, -(1 - cos a) / a], [(1 - cos a) / a, sin a / a]]
    sa = np.where(small, 1.0 - a * a / 6.0, np.sin(a_safe) / a_safe)
    ca = np.where(small, a / 2.0, (1.0 - np.cos(a_safe)) / a_safe)
    d_body = np.stack([dt * (sa * v[..., 0] - ca * v[..., 1]), dt * (ca * v[..., 0] + sa * v[..., 1])], axis=-1)
    d = body_to_world(p[..., 2], d_body)
    return np.concatenate([p[..., :2] + d, (p[..., 2] + a)[..., None]], axis=-1)


def _twist_arc_one(x, y, th, u, w, r, dt) -> np.ndarray:
    """:func:`twist_arc` of one pose in scalar math (the pose filter's Jacobian calls it 7 times a frame)."""
    a = r * dt
    if abs(a) < 1e-6:
        sa, ca = 1.0 - a * a / 6.0, a / 2.0
    else:
        sa, ca = math.sin(a) / a, (1.0 - math.cos(a)) / a
    bx, by = dt * (sa * u - ca * w), dt * (ca * u + sa * w)
    c, s = math.cos(th), math.sin(th)
    return np.array([x + c * bx - s * by, y + s * bx + c * by, th + a])
