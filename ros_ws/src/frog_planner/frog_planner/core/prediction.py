"""Apply a library transition to a world pose (paper seed 000, eq. 18).

A transition holds the state after one period, expressed in the body frame of the start
pose: displacement (x_next, y_next) m, heading change theta_next rad, and the body velocities
at the end (forward, lateral m/s, yaw rate rad/s) in the body frame at that time
(docs/motion_library_format.md). Eq. 18:

    [x, y](t+T) = [x, y](t) + R(theta(t)) [x_next, y_next]
    theta(t+T)  = theta(t) + theta_next
    [x_dot, y_dot](t+T) = R(theta(t+T)) [u_next, v_next]   (velocities are in the end body frame)
    theta_dot(t+T) = theta_dot_next
"""

import numpy as np
from frog_common.se2 import wrap_angle


def apply_transition(pose, transition):
    """Pose and body velocity after a transition (eq. 18), broadcasting over leading axes.

    Parameters
    ----------
    pose : array_like, shape (..., 3)
        x m, y m, heading rad in the world frame.
    transition : array_like, shape (..., 6)
        x_next m, y_next m, theta_next rad, forward m/s, lateral m/s, yaw rate rad/s.

    Returns
    -------
    next_pose : numpy.ndarray, shape (..., 3)
        World pose after T; heading wrapped to [-pi, pi).
    next_body_velocity : numpy.ndarray, shape (..., 3)
        Body velocity after T (the transition's last three entries), ready for the next lookup.

    Examples
    --------
    >>> apply_transition([1.0, 0.0, np.pi / 2], [0.1, 0.0, 0.2, 0.03, 0.0, 0.1])[0].round(3)
    array([1.   , 0.1  , 1.771])
    """
    p = np.asarray(pose, dtype=float)
    t = np.asarray(transition, dtype=float)
    c, s = np.cos(p[..., 2]), np.sin(p[..., 2])
    x = p[..., 0] + c * t[..., 0] - s * t[..., 1]
    y = p[..., 1] + s * t[..., 0] + c * t[..., 1]
    heading = wrap_angle(p[..., 2] + t[..., 2])
    next_pose = np.stack(np.broadcast_arrays(x, y, heading), axis=-1)
    next_velocity = np.broadcast_to(t[..., 3:6], next_pose.shape).copy()
    return next_pose, next_velocity


def predict_world_state(state, transition):
    """World state after a transition (full eq. 18, velocities in the world frame).

    Parameters
    ----------
    state : array_like, shape (..., 6)
        x m, y m, heading rad, x_dot m/s, y_dot m/s, heading rate rad/s (world frame).
        Only the pose part is used: the next state follows from the transition alone.
    transition : array_like, shape (..., 6)
        As for :func:`apply_transition`.

    Returns
    -------
    numpy.ndarray, shape (..., 6)
        World state after T.
    """
    s = np.asarray(state, dtype=float)
    pose, body_velocity = apply_transition(s[..., :3], transition)
    c, sn = np.cos(pose[..., 2]), np.sin(pose[..., 2])
    vx = c * body_velocity[..., 0] - sn * body_velocity[..., 1]
    vy = sn * body_velocity[..., 0] + c * body_velocity[..., 1]
    return np.concatenate([pose, np.stack([vx, vy, body_velocity[..., 2]], axis=-1)], axis=-1)
