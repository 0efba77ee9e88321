"""Planar rigid-body motion shared by the renderer (motion blur) and the pose filter (prediction)."""

import numpy as np


def integrate_twist(pose, twist, dt: float) -> np.ndarray:
    """Pose after moving for ``dt`` [s] at a constant body twist (forward, lateral, yaw rate)."""
    x, y, a = pose
    vx, vy, w = twist
    if abs(w * dt) < 1e-9:
        dx, dy = vx * dt, vy * dt
    else:
        s, c = np.sin(w * dt), np.cos(w * dt)
        dx = (vx * s - vy * (1 - c)) / w
        dy = (vx * (1 - c) + vy * s) / w
    ca, sa = np.cos(a), np.sin(a)
    return np.array([x + ca * dx - sa * dy, y + sa * dx + ca * dy, a + w * dt])
