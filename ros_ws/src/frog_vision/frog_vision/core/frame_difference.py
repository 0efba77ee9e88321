"""The authors' state estimate: the tag pose as measured, velocities as frame-to-frame differences.

The paper's tracker (seed 000; its logs' ``xdot``, ``ydot``, ``thetadot`` columns, see
``../shared/data/frog/hardware_runs/README.md``) gave the planner the raw pose of each frame and
the difference to the previous frame divided by the frames' time gap, at about 14 fps. At the
robot's pose noise that yaw rate is noisier than the yaw rate itself (sd about 0.34 rad/s
against 0.23 rad/s of signal in the sine runs). :class:`FrameDifferenceEstimator` reproduces
it behind :class:`~frog_vision.core.state_filter.PoseFilter`'s interface, so the twin can run
the paper's planner on the state the robot's planner saw (``tracker_node estimator``).
"""
from __future__ import annotations

import numpy as np

from frog_vision.core.state_filter import FilterSettings, RobotState
from frog_common.se2 import wrap_angle


def raw_differences(stamps, poses) -> np.ndarray:
    """Frame-to-frame differences of the poses, rotated into the body frame at the newer pose's
    heading -> (N, 3) forward [m/s], lateral [m/s], yaw rate [rad/s] (first row NaN)."""
    t = np.asarray(stamps, float)
    p = np.asarray(poses, float)
    out = np.full((len(t), 3), np.nan)
    if len(t) < 2:
        return out
    dt = np.diff(t)
    d = np.diff(p, axis=0)
    d[:, 2] = wrap_angle(d[:, 2])
    v = d / dt[:, None]
    th = p[1:, 2]
    c, s = np.cos(th), np.sin(th)
    out[1:, 0] = c * v[:, 0] + s * v[:, 1]
    out[1:, 1] = -s * v[:, 0] + c * v[:, 1]
    out[1:, 2] = v[:, 2]
    return out


class FrameDifferenceEstimator:
    """Pose = the last measurement; body twist = the difference to the measurement before it.

    Uses ``coast_timeout`` and ``reset_timeout`` of :class:`FilterSettings` as the filter does:
    without a measurement the last state is held (not predicted) for ``coast_timeout``, and after
    ``reset_timeout`` the next measurement starts again with a zero twist. Kick inputs are
    ignored (the authors' tracker had none). The heading is kept continuous (unwrapped).

    Examples
    --------
    >>> e = FrameDifferenceEstimator()
    >>> _ = e.update(0.0, np.array([0.0, 0.0, 0.0]), np.eye(3) * 1e-8)
    >>> s, _ = e.update(0.1, np.array([0.002, 0.0, 0.0]), np.eye(3) * 1e-8)
    >>> round(float(s.body_velocity[0]), 6)
    0.02
    """

    def __init__(self, settings: FilterSettings | None = None):
        self.settings = settings or FilterSettings()
        self.n_rejected = 0
        self.n_resets = 0
        self.reset()

    def reset(self) -> None:
        """Forget the state; the next measurement starts again."""
        self._z: np.ndarray | None = None
        self._R: np.ndarray | None = None
        self._twist = np.zeros(3)
        self._twist_cov = np.zeros((3, 3))
        self.t: float | None = None
        self.last_measurement: float | None = None

    @property
    def initialised(self) -> bool:
        return self._z is not None

    def kick(self, t: float) -> None:
        """Ignored: the authors' estimate knows nothing of the inputs (same check as the filter)."""
        if not np.isfinite(t):
            raise ValueError(f"kick time {t!r} is not finite")

    def update(self, t: float, z: np.ndarray, R: np.ndarray) -> tuple[RobotState, str | None]:
        """Take the pose ``z`` = (x, y, heading) with covariance ``R`` measured at ``t``."""
        z = np.asarray(z, float).copy()
        R = np.asarray(R, float)
        if not (np.all(np.isfinite(z)) and np.all(np.isfinite(R))):
            raise ValueError(f"measurement {z} or its covariance is not finite")
        if self._z is not None and t <= self.t:
            return self.state(self.t), f"measurement at {t:.3f} s is not newer than the state ({self.t:.3f} s)"
        if self._z is not None and t - self.last_measurement > self.settings.reset_timeout:
            self.reset()
            self.n_resets += 1
        if self._z is None:
            self._twist, self._twist_cov = np.zeros(3), np.zeros((3, 3))
        else:
            z[2] = self._z[2] + wrap_angle(z[2] - self._z[2])   # continuous heading
            dt = t - self.t
            self._twist = raw_differences([self.t, t], [self._z, z])[1]
            c, s = np.cos(z[2]), np.sin(z[2])
            rot = np.array([[c, s, 0], [-s, c, 0], [0, 0, 1.0]])          # world -> body
            self._twist_cov = rot @ (R + self._R) @ rot.T / dt ** 2       # independent frame noise
        self._z, self._R = z, R
        self.t = self.last_measurement = float(t)
        return self.state(t), None

    def state(self, t: float, coasting: bool | None = None) -> RobotState | None:
        """The last state, held (not predicted) up to ``coast_timeout`` after the last measurement."""
        if self._z is None or t - self.last_measurement > self.settings.coast_timeout:
            return None
        coast = (t > self.last_measurement) if coasting is None else coasting
        return RobotState(float(t), self._z.copy(), self._twist.copy(), self._R.copy(), self._twist_cov.copy(),
                          coast)
