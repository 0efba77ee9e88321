"""Position, heading, body velocities and yaw rate from the tag's pose stream.

An extended Kalman filter with a constant *body* twist model (the robot moves along an
arc between frames, so a steady turn gives no lag, unlike a world-frame constant-velocity
filter), state ``[x, y, theta, u, v, omega]``: tank-frame pose and body-frame forward,
lateral and yaw-rate velocities. It is driven by white acceleration noise: per axis, over a
step dt, ``Q = q [[dt^3/3, dt^2/2], [dt^2/2, dt]]`` with the spectral densities
``accel_noise`` [(m/s^2)^2/Hz] and ``yaw_accel_noise`` [(rad/s^2)^2/Hz] (Bar-Shalom,
"Estimation with Applications to Tracking", sec. 6.2.2).
The defaults were tuned on rendered sequences of frog_sim's simulated frog executing
primitives, with the authors' level of pose noise (``bench/vision_accuracy.py``): smaller
values smooth more but lag more behind a stroke. For faster manoeuvres (the synthetic
sequences' 20 deg/s turning strokes) a larger ``yaw_accel_noise`` (0.1) is better.

Kick inputs (optional, :meth:`PoseFilter.kick`): the frog moves by impulses, an SMA stroke
accelerating it within ~0.35 s, then it coasts, slowing down by drag over seconds. A single
process noise either lags the strokes or passes the pose noise through while it coasts. When
the filter is told when limbs were fired (the bridge's ``frog/bridge/sent``, stamped at the
write), it uses ``kick_accel_noise`` / ``kick_yaw_accel_noise`` for ``kick_window`` seconds
after each firing (``kick_delay`` later), and the low ``coast_accel_noise`` / ``coast_yaw_accel_noise`` otherwise
(a step partly inside a window gets the time-weighted mean density), and while coasting
the body twist decays by drag, ``d twist/dt = -twist / coast_drag_time`` (per axis; the
frog slows from ~30 to ~20 mm/s over a 1.5 s primitive period). This switch is made by
the first kick reported: from then on the filter assumes that every firing is reported
(nothing else makes the robot accelerate; a robot moved by hand is still caught by the
jump restart below). Without kick inputs it uses ``accel_noise`` / ``yaw_accel_noise``
throughout, as a filter that knows nothing about the inputs must. The estimate stays causal:
a kick only changes the predictions after its stamp.

Heading measurements are unwrapped against the prediction; measurements further than a
chi-square gate from the prediction are rejected as outliers (a wrong quad, a tag half out
of view) unless several in a row agree (then the robot really moved: the filter restarts
there). Without measurements the filter coasts (prediction only) for up to
``coast_timeout``; after ``reset_timeout`` without a measurement it forgets the state and
starts again from the next measurement. All times are the image capture stamps [s].
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
from frog_common.se2 import twist_arc
from frog_common.se2 import wrap_angle
from frog_common.settings import Settings, setting

#: Chi-square 99.9 % quantile with 3 degrees of freedom.
CHI2_3DOF_999 = 16.27


@dataclasses.dataclass(frozen=True)
class FilterSettings(Settings):
    """Settings of :class:`PoseFilter` (see the module docstring); tracker_node's parameters."""

    accel_noise: float = setting(3e-5, "filter: linear acceleration noise density", min=1e-9, max=100.0,
                                 unit="(m/s^2)^2/Hz", live=True)
    yaw_accel_noise: float = setting(0.01, "filter: yaw acceleration noise density", min=1e-9, max=1000.0,
                                     unit="(rad/s^2)^2/Hz", live=True)
    gate_chi2: float = setting(CHI2_3DOF_999, "chi-square gate of a measurement against the prediction",
                               min=0.1, max=1e4)
    gate_floor_m: float = setting(0.003, "never gate closer than this (position)", min=0.0, max=1.0, unit="m")
    gate_floor_rad: float = setting(0.05, "never gate closer than this (heading)", min=0.0, max=3.2, unit="rad")
    jump_confirmations: int = setting(3, "consecutive out-of-gate measurements that restart the filter",
                                      min=1, max=100)
    coast_timeout: float = setting(0.5, "publish predictions this long after the tag is lost", min=1e-3,
                                   max=10.0, unit="s")
    reset_timeout: float = setting(1.0, "restart the filter after the tag was lost this long", min=1e-3,
                                   max=60.0, unit="s")
    initial_speed_sigma: float = setting(0.05, "initial velocity uncertainty", min=1e-6, max=10.0, unit="m/s")
    initial_yaw_rate_sigma: float = setting(1.0, "initial yaw rate uncertainty", min=1e-6, max=100.0,
                                            unit="rad/s")
    # with kick inputs (see the module docstring); tuned on the same rendered sequences with the
    # simulator's firing times (bench/vision_accuracy.py): a window after each pulse start (front
    # limbs, rear limbs 80 ms later) covers the ~0.35 s power stroke
    kick_window: float = setting(0.2, "filter with kicks: follow the stroke this long after each firing",
                                 min=0.01, max=5.0, unit="s", live=True)
    # the simulator reacts at once; raise it for a robot whose stroke lags the write
    kick_delay: float = setting(0.0, "filter with kicks: from a firing's stamp to the start of its window",
                                min=0.0, max=2.0, unit="s", live=True)
    kick_accel_noise: float = setting(1e-4, "filter with kicks: linear acceleration noise density in a kick "
                                      "window", min=1e-9, max=100.0, unit="(m/s^2)^2/Hz", live=True)
    kick_yaw_accel_noise: float = setting(1.0, "filter with kicks: yaw acceleration noise density in a kick "
                                          "window", min=1e-9, max=1000.0, unit="(rad/s^2)^2/Hz", live=True)
    coast_accel_noise: float = setting(3e-6, "filter with kicks: linear acceleration noise density between "
                                       "kicks", min=1e-12, max=100.0, unit="(m/s^2)^2/Hz", live=True)
    coast_yaw_accel_noise: float = setting(1e-3, "filter with kicks: yaw acceleration noise density between "
                                           "kicks", min=1e-12, max=1000.0, unit="(rad/s^2)^2/Hz", live=True)
    coast_drag_time: float = setting(8.0, "filter with kicks: decay time of the body velocities between kicks; "
                                     "0 = no drag", min=1e-3, max=1000.0, unit="s", live=True,
                                     sentinel=(0.0, math.inf))
    coast_yaw_drag_time: float = setting(5.0, "filter with kicks: decay time of the yaw rate between kicks; "
                                         "0 = no drag", min=1e-3, max=1000.0, unit="s", live=True,
                                         sentinel=(0.0, math.inf))

    def cross_check(self) -> str | None:
        if self.reset_timeout < self.coast_timeout:
            return f"reset_timeout = {self.reset_timeout} must be >= coast_timeout = {self.coast_timeout}"
        return None


@dataclasses.dataclass(frozen=True)
class RobotState:
    """Filtered state at ``stamp``.

    Attributes
    ----------
    stamp : float
        [s] (the capture time of the last image used).
    pose : ndarray (3,)
        x [m], y [m], heading [rad] (continuous, not wrapped).
    body_velocity : ndarray (3,)
        forward [m/s], lateral (left) [m/s], yaw rate [rad/s] (REP-105 child-frame twist).
    pose_covariance, twist_covariance : ndarray (3, 3)
        Of (x, y, heading) in the tank frame, and of the body velocities.
    coasting : bool
        No measurement at ``stamp`` (prediction only).
    """

    stamp: float
    pose: np.ndarray
    body_velocity: np.ndarray
    pose_covariance: np.ndarray
    twist_covariance: np.ndarray
    coasting: bool


class PoseFilter:
    """Constant-body-twist extended Kalman filter on planar poses.

    Examples
    --------
    >>> f = PoseFilter()
    >>> for k in range(30):
    ...     s, _ = f.update(k / 30, np.array([0.01 * k / 30, 0.0, 0.0]), np.eye(3) * 1e-8)
    >>> round(float(s.body_velocity[0]), 3)
    0.01
    """

    def __init__(self, settings: FilterSettings | None = None):
        self.settings = settings or FilterSettings()
        self.kicks: list[float] = []        # the robot's inputs, not the track's: kept over resets
        self.inputs_known = False
        self.reset()

    def reset(self) -> None:
        """Forget the state; the next measurement starts the filter."""
        self.x: np.ndarray | None = None
        self.P: np.ndarray | None = None
        self.t: float | None = None
        self.last_measurement: float | None = None
        self._rejected: list = []
        self.n_rejected = 0
        self.n_resets = 0

    def kick(self, t: float) -> None:
        """Limbs were fired at ``t`` [s] (same clock as the image stamps): inflate the process
        noise for ``kick_window`` after ``t`` and, from now on, keep it low between kicks.

        Raises
        ------
        ValueError
            ``t`` is not finite.
        """
        if not np.isfinite(t):
            raise ValueError(f"kick time {t!r} is not finite")
        self.inputs_known = True
        # windows that ended before the state's time cannot overlap a later step
        now = self.t if self.t is not None else -np.inf
        s = self.settings
        self.kicks = [k for k in self.kicks if k + s.kick_delay + s.kick_window > now] + [float(t)]

    def _process_model(self, t0: float, t1: float) -> tuple[np.ndarray, np.ndarray]:
        """Spectral densities (x, y, yaw) over the step t0 -> t1 (mean over the step) and the
        twist's decay exponents over it (the twist is multiplied by ``exp(-rate)``)."""
        s = self.settings
        if not self.inputs_known:
            return np.array([s.accel_noise] * 2 + [s.yaw_accel_noise]), np.zeros(3)
        # time inside the union of kick windows during the step
        inside, end = 0.0, t0
        for k in sorted(self.kicks):
            a, b = max(k + s.kick_delay, end), min(k + s.kick_delay + s.kick_window, t1)
            if b > a:
                inside += b - a
                end = b
        f = inside / (t1 - t0)
        low = np.array([s.coast_accel_noise] * 2 + [s.coast_yaw_accel_noise])
        high = np.array([s.kick_accel_noise] * 2 + [s.kick_yaw_accel_noise])
        # drag only while coasting (inside a window the limbs drive the robot)
        rate = (1 - f) * (t1 - t0) / np.array([s.coast_drag_time] * 2 + [s.coast_yaw_drag_time])
        return (1 - f) * low + f * high, rate

    @property
    def initialised(self) -> bool:
        return self.x is not None

    def _start(self, t, z, R) -> None:
        s = self.settings
        self.x = np.concatenate([z, np.zeros(3)])
        self.P = np.zeros((6, 6))
        self.P[:3, :3] = R
        self.P[3:, 3:] = np.diag([s.initial_speed_sigma ** 2] * 2 + [s.initial_yaw_rate_sigma ** 2])
        self.t = self.last_measurement = t
        self._rejected = []

    def _predicted(self, t) -> tuple[np.ndarray, np.ndarray]:
        dt = t - self.t
        if dt <= 0:
            return self.x.copy(), self.P.copy()
        q, r = self._process_model(self.t, t)
        decay = np.exp(-r)
        # constant body twist: the pose moves along an arc (exact), the twist stays; coasting with
        # drag (decay < 1), the arc at the step's mean twist (the twist changes < 1 % per frame)
        mean = np.where(r > 1e-12, -np.expm1(-r) / np.maximum(r, 1e-12), 1.0)
        x = np.concatenate([twist_arc(self.x[:3], mean * self.x[3:], dt), decay * self.x[3:]])
        F = np.eye(6)
        F[3:, 3:] = np.diag(decay)
        h = 1e-6
        for j in range(3, 6):                       # d pose / d twist (numerical), d pose / d heading
            dx = np.zeros(3)
            dx[j - 3] = h
            F[:3, j] = (twist_arc(self.x[:3], mean * (self.x[3:] + dx), dt)
                        - twist_arc(self.x[:3], mean * (self.x[3:] - dx), dt)) / (2 * h)
        dth = np.array([0, 0, h])
        F[:3, 2] = (twist_arc(self.x[:3] + dth, mean * self.x[3:], dt)
                    - twist_arc(self.x[:3] - dth, mean * self.x[3:], dt)) / (2 * h)
        Q = np.zeros((6, 6))
        Q[:3, :3] = np.diag(q * dt ** 3 / 3)
        Q[3:, 3:] = np.diag(q * dt)
        c, sn = np.cos(self.x[2]), np.sin(self.x[2])
        rot = np.array([[c, -sn, 0], [sn, c, 0], [0, 0, 1.0]])       # body -> world
        Q[:3, 3:] = rot @ np.diag(q * dt ** 2 / 2)
        Q[3:, :3] = Q[:3, 3:].T
        return x, F @ self.P @ F.T + Q

    def update(self, t: float, z: np.ndarray, R: np.ndarray) -> tuple[RobotState, str | None]:
        """Fold in a pose measurement ``z`` = (x, y, heading) with covariance ``R`` taken at
        capture time ``t``.

        Returns
        -------
        (RobotState, str or None)
            The state after the update and, when the measurement was not used, why.
        """
        z = np.asarray(z, float)
        R = np.asarray(R, float)
        if not (np.all(np.isfinite(z)) and np.all(np.isfinite(R))):
            raise ValueError(f"measurement {z} or its covariance is not finite")
        s = self.settings
        if self.x is not None and t < self.t:
            return self.state(self.t), f"measurement at {t:.3f} s is older than the state ({self.t:.3f} s)"
        if self.x is not None and t - self.last_measurement > s.reset_timeout:
            self.reset()
            self.n_resets += 1
        if self.x is None:
            self._start(t, z, R)
            return self.state(t), None
        x, P = self._predicted(t)
        innov = z - x[:3]
        innov[2] = wrap_angle(innov[2])      # heading unwrapped against the prediction
        S = P[:3, :3] + R
        floor = np.diag([s.gate_floor_m ** 2] * 2 + [s.gate_floor_rad ** 2])
        d2 = float(innov @ np.linalg.solve(S + floor, innov))
        if d2 > s.gate_chi2:
            self.n_rejected += 1
            self._rejected.append((t, z, R))
            if len(self._rejected) >= s.jump_confirmations and self._consistent(self._rejected):
                t0, z0, R0 = self._rejected[-1]
                z0 = z0.copy()
                z0[2] += 2 * np.pi * np.round((x[2] - z0[2]) / (2 * np.pi))   # keep heading continuous
                self._start(t0, z0, R0)
                self.n_resets += 1
                return self.state(t), None
            return self.state(t, coasting=True), f"outlier (Mahalanobis distance^2 {d2:.0f})"
        self._rejected = []
        K = P[:, :3] @ np.linalg.inv(S)
        self.x = x + K @ innov
        IKH = np.eye(6) - K[:, :3] @ np.eye(3, 6)
        self.P = IKH @ P @ IKH.T + K @ R @ K.T           # Joseph form: stays symmetric PSD
        self.t = self.last_measurement = t
        return self.state(t), None

    def _consistent(self, rejected) -> bool:
        """Recent outliers agree with each other (the robot is really there)."""
        zs = np.array([z for _, z, _ in rejected[-self.settings.jump_confirmations:]])
        spread = np.ptp(zs[:, :2], axis=0).max()
        return spread < 0.05

    def state(self, t: float, coasting: bool | None = None) -> RobotState | None:
        """The state predicted to time ``t`` (``None`` if not initialised or the last
        measurement is older than ``coast_timeout``)."""
        if self.x is None or t - self.last_measurement > self.settings.coast_timeout:
            return None
        x, P = self._predicted(t) if t > self.t else (self.x, self.P)
        coast = (t > self.last_measurement) if coasting is None else coasting
        return RobotState(float(t), x[:3].copy(), x[3:].copy(), P[:3, :3].copy(), P[3:, 3:].copy(), coast)
