"""Online identification of the robot's four limb strengths from its tracked motion (issue 19).

Beyond the paper: real limbs differ (SMA wire, attachment, EGaIn fill; the twin draws each
limb's kick from N(1, 0.1^2), and the authors' robot swam right on its straight runs), while
the simulator in the planning loop assumes four equal ones. Every decision, the motion since
the previous decision is simulated again from the previous estimate (pose, twist, the limbs'
firing times) with the limbs as they were actually fired, and compared with where the robot
is now tracked; an extended Kalman filter moves the log-strengths of the limbs involved
(fired in the window or still relaxing from an earlier firing) by that residual. The
Jacobian is by forward differences: one rollout of the window per limb involved.

The state is ``log(strength)`` per limb (strengths stay positive), with a prior N(0,
``prior_sd``^2) and a random walk of ``drift_sd`` per update (an SMA wire changes with the
battery and the water). The residual's noise (``noise``) is what the model cannot explain
from one period to the next: the kick-to-kick spread and the tank's yaw torque (``frog-sim
disturbance``: 4.3 deg of heading per period on the authors' runs) and the tracker's noise.

A planner uses :meth:`LimbIdentification.start` instead of ``Rollouts.estimated_start``:
it learns from the motion since its previous call, sets the rollouts' limb strengths to the
estimate and returns this decision's start.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from frog_common.primitives import LIMB_IDS, LIMB_NAMES
from frog_common.se2 import wrap_angle

#: Residual sd per component: dx, dy [m] and dyaw [rad] in the previous pose's frame, then the
#: body twist u, v [m/s], w [rad/s] (kick spread, yaw disturbance, tracker noise over a period).
NOISE = (0.004, 0.004, 0.075, 0.004, 0.004, 0.06)
#: Forward-difference step in log-strength.
STEP = 0.05
#: A limb fired this long before the window still moves the body (its recovery stroke) [s].
RELAXING_S = 1.5
#: Strengths are kept within these factors of nominal.
BOUNDS = (0.3, 3.0)


@dataclass
class _Observation:
    now: float
    pose: np.ndarray
    twist: np.ndarray
    fired: dict          # limb name -> time of its last firing (the caller's clock)


class LimbIdentification:
    """Limb strengths of the robot, learned online from what it did (see the module doc).

    Parameters
    ----------
    rollouts : frog_sim.core.rollouts.Rollouts
        Whose limb strengths are set to the estimate at every :meth:`start`.
    prior_sd : float
        Prior sd of each log-strength (0.1: the twin's spread).
    drift_sd : float
        Random-walk sd of each log-strength per update.
    noise : sequence of 6 floats
        Residual sd of dx, dy [m], dyaw [rad], u, v [m/s], w [rad/s].
    max_gap : float
        Observations further apart than this [s] are not compared (a missed decision).
    """

    def __init__(self, rollouts, prior_sd: float = 0.1, drift_sd: float = 0.005, noise=NOISE,
                 max_gap: float = 2.5):
        noise = np.asarray(noise, dtype=float)
        if noise.shape != (6,) or not np.all(np.isfinite(noise) & (noise > 0)):
            raise ValueError(f"noise {noise.tolist()} must be 6 positive numbers (dx, dy, dyaw, u, v, w)")
        for name, value in (("prior_sd", prior_sd), ("drift_sd", drift_sd), ("max_gap", max_gap)):
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} = {value!r} must be a finite number >= 0")
        self.rollouts = rollouts
        self._config = (prior_sd, drift_sd, noise, max_gap)
        self.log_strength = np.zeros(len(LIMB_NAMES))
        self.cov = np.eye(len(LIMB_NAMES)) * prior_sd ** 2
        self.drift_var = drift_sd ** 2
        self.noise_var = noise ** 2
        self.max_gap = float(max_gap)
        self.updates = 0
        self.last_residual = None      # observed - predicted of the last update (6,)
        self._previous = None

    @property
    def strengths(self) -> dict:
        """Limb name -> estimated kick strength (1 = nominal)."""
        return {limb: float(math.exp(v)) for limb, v in zip(LIMB_NAMES, self.log_strength)}

    @property
    def sd(self) -> dict:
        """Limb name -> sd of the estimate's log-strength (about the relative sd of the strength)."""
        return {limb: float(math.sqrt(v)) for limb, v in zip(LIMB_NAMES, np.diag(self.cov))}

    def reset(self) -> None:
        """Forget what was learned and the previous observation (a new robot)."""
        self.__init__(self.rollouts, *self._config)

    def start(self, now: float, pose, twist, last_fired=None):
        """This decision's rollout start, after learning from the motion since the previous call.

        Parameters
        ----------
        now : float
            Time of the pose [s] on the caller's clock.
        pose, twist : array_like, shape (3,)
            Tracked pose (x, y [m], yaw [rad]) and body twist (u, v [m/s], w [rad/s]).
        last_fired : mapping, optional
            Limb name -> time of its last firing [s] on the same clock (up to ``now``).

        Returns
        -------
        RolloutStart
            ``Rollouts.estimated_start`` with the rollouts' limbs at the new estimate.
        """
        obs = _Observation(float(now), np.asarray(pose, dtype=float), np.asarray(twist, dtype=float),
                           {k: float(v) for k, v in dict(last_fired or {}).items()})
        prev, self._previous = self._previous, obs
        if prev is not None and 0.0 < obs.now - prev.now <= self.max_gap:
            self._update(prev, obs)
        self.rollouts.set_limb_strength(self.strengths)
        return self.rollouts.estimated_start(obs.pose, obs.twist, obs.fired, now=obs.now)

    # ------------------------------------------------------------------ the filter
    def _predict(self, log_strength, prev: _Observation, window: dict, duration: float):
        """dx, dy, dyaw (previous pose's frame), u, v, w after ``duration`` with these strengths."""
        self.rollouts.set_limb_strength(dict(zip(LIMB_NAMES, np.exp(log_strength).tolist())))
        start = self.rollouts.estimated_start(prev.pose, prev.twist, prev.fired, now=prev.now)
        end = self.rollouts.run_firings(start, window, duration)
        if end is None:
            return None
        return self._relative(prev.pose, end.pose, end.twist)

    @staticmethod
    def _relative(origin, pose, twist) -> np.ndarray:
        c, s = math.cos(origin[2]), math.sin(origin[2])
        dx, dy = pose[0] - origin[0], pose[1] - origin[1]
        return np.array([c * dx + s * dy, -s * dx + c * dy, wrap_angle(pose[2] - origin[2]), *twist])

    def _update(self, prev: _Observation, obs: _Observation) -> None:
        duration = obs.now - prev.now
        # what fired after the previous observation: newer than it knew, not before it (a firing
        # at the observation's own instant, after it was taken, belongs to the window)
        window = {limb: max(t - prev.now, 0.0) for limb, t in obs.fired.items()
                  if prev.now - 1e-9 <= t <= obs.now and t > prev.fired.get(limb, -math.inf) + 1e-9}
        involved = sorted({LIMB_IDS[limb] for limb in window}
                          | {LIMB_IDS[limb] for limb, t in prev.fired.items() if prev.now - t < RELAXING_S})
        if not involved:
            return                                  # nothing fired or relaxing: the strengths do not show
        base = self._predict(self.log_strength, prev, window, duration)
        if base is None:
            return
        jac = np.zeros((6, len(LIMB_NAMES)))
        for lid in involved:
            shifted = self.log_strength.copy()
            shifted[lid] += STEP
            moved = self._predict(shifted, prev, window, duration)
            if moved is None:
                return
            jac[:, lid] = (moved - base) / STEP
        residual = self._relative(prev.pose, obs.pose, obs.twist) - base
        residual[2] = wrap_angle(residual[2])
        cov = self.cov + np.eye(len(LIMB_NAMES)) * self.drift_var
        innovation = jac @ cov @ jac.T + np.diag(self.noise_var)
        gain = cov @ jac.T @ np.linalg.inv(innovation)
        lo, hi = np.log(BOUNDS)
        self.log_strength = np.clip(self.log_strength + gain @ residual, lo, hi)
        self.cov = (np.eye(len(LIMB_NAMES)) - gain @ jac) @ cov
        self.cov = 0.5 * (self.cov + self.cov.T)
        self.updates += 1
        self.last_residual = residual
