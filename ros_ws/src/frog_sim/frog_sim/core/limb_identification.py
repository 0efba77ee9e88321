"""Online identification of the robot's four limb strengths from its tracked motion.

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

With ``torque_sd`` > 0 the filter also estimates the tank's yaw torque (beyond the paper;
:mod:`~frog_sim.core.yaw_disturbance`): an Ornstein-Uhlenbeck process of stationary sd
``torque_sd`` and time constant ``Rollouts.yaw_torque_tau``, so its value now says something
about the next period (the robot's heading residuals correlate 0.63 from one period to the
next). The state gains the torque at the last observation, ``N0``. For an update the state is
augmented with the torque now, ``N1 = a N0 + w`` (``a = exp(-dt / tau)``, ``var w = sd^2 (1 -
a^2)``); the window is rolled out with the torque on the OU bridge's mean from ``N0`` to ``N1``
(``Rollouts.run_firings``), with one more rollout per torque for the Jacobian; after the
update ``N0`` is marginalised out, so the state holds the torque now with all the window says
about it (carrying ``N0`` over by ``a`` would lose what the window's end shows). The
decision's rollouts start with it (``RolloutStart.yaw_torque``), decaying with ``tau``.

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
#: The yaw torque is kept within this many stationary sd of 0.
TORQUE_BOUND_SD = 4.0
_N_LIMBS = len(LIMB_NAMES)
_TORQUE = _N_LIMBS       # the torque's index in the state


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
    torque_sd : float
        Stationary sd of the tank's yaw torque [N m] (e.g.
        :data:`~frog_sim.core.yaw_disturbance.TANK_YAW_TORQUE_SD`); 0: not estimated (none).
    """

    def __init__(self, rollouts, prior_sd: float = 0.1, drift_sd: float = 0.005, noise=NOISE,
                 max_gap: float = 2.5, torque_sd: float = 0.0):
        noise = np.asarray(noise, dtype=float)
        if noise.shape != (6,) or not np.all(np.isfinite(noise) & (noise > 0)):
            raise ValueError(f"noise {noise.tolist()} must be 6 positive numbers (dx, dy, dyaw, u, v, w)")
        for name, value in (("prior_sd", prior_sd), ("drift_sd", drift_sd), ("max_gap", max_gap),
                            ("torque_sd", torque_sd)):
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} = {value!r} must be a finite number >= 0")
        self.rollouts = rollouts
        self._config = (prior_sd, drift_sd, noise, max_gap, torque_sd)
        # the state: the limbs' log-strengths, then the yaw torque [N m] at the last observation
        self.state = np.zeros(_N_LIMBS + 1)
        self.cov = np.diag([prior_sd ** 2] * _N_LIMBS + [torque_sd ** 2])
        self.torque_sd = float(torque_sd)
        self.drift_var = drift_sd ** 2
        self.noise_var = noise ** 2
        self.max_gap = float(max_gap)
        self.updates = 0
        self.last_residual = None      # observed - predicted of the last update (6,)
        self._previous = None

    @property
    def log_strength(self) -> np.ndarray:
        """The limbs' estimated log-strengths (FL, FR, BL, BR)."""
        return self.state[:_N_LIMBS]

    @property
    def strengths(self) -> dict:
        """Limb name -> estimated kick strength (1 = nominal)."""
        return {limb: float(math.exp(v)) for limb, v in zip(LIMB_NAMES, self.log_strength)}

    @property
    def sd(self) -> dict:
        """Limb name -> sd of the estimate's log-strength (about the relative sd of the strength)."""
        return {limb: float(math.sqrt(v)) for limb, v in zip(LIMB_NAMES, np.diag(self.cov))}

    @property
    def torque(self) -> float:
        """The estimated yaw torque at the last observation [N m] (0 when not estimated)."""
        return float(self.state[_TORQUE])

    @property
    def torque_estimate_sd(self) -> float:
        """Its sd [N m]."""
        return float(math.sqrt(self.cov[_TORQUE, _TORQUE]))

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
        if prev is not None and obs.now > prev.now:
            if not (obs.now - prev.now <= self.max_gap and self._update(prev, obs)):
                self._carry_torque(obs.now - prev.now)
        self.rollouts.set_limb_strength(self.strengths)
        return self.rollouts.estimated_start(obs.pose, obs.twist, obs.fired, now=obs.now, yaw_torque=self.torque)

    # ------------------------------------------------------------------ the filter
    def _carry_torque(self, dt: float) -> None:
        """The torque from the last observation to ``dt`` [s] later, learning nothing: its OU mean
        and variance."""
        state, cov = self._augmented(dt)
        keep = [*range(_N_LIMBS), _TORQUE + 1]
        self.state, self.cov = state[keep], cov[np.ix_(keep, keep)]

    def _augmented(self, dt: float):
        """State and covariance with the torque ``dt`` [s] after the last observation appended."""
        a = math.exp(-dt / self.rollouts.yaw_torque_tau)
        n = self.state.size
        lift = np.vstack([np.eye(n), np.eye(n)[_TORQUE] * a])
        cov = lift @ self.cov @ lift.T
        cov[n, n] += self.torque_sd ** 2 * (1.0 - a * a)
        return lift @ self.state, cov

    def _predict(self, state, prev: _Observation, window: dict, duration: float):
        """dx, dy, dyaw (previous pose's frame), u, v, w after ``duration`` with these strengths
        and the torque from ``state[_TORQUE]`` at ``prev`` to ``state[_TORQUE + 1]`` at the end."""
        self.rollouts.set_limb_strength(dict(zip(LIMB_NAMES, np.exp(state[:_N_LIMBS]).tolist())))
        start = self.rollouts.estimated_start(prev.pose, prev.twist, prev.fired, now=prev.now,
                                              yaw_torque=float(state[_TORQUE]))
        end = self.rollouts.run_firings(start, window, duration, yaw_torque_end=float(state[_TORQUE + 1]))
        if end is None:
            return None
        return self._relative(prev.pose, end.pose, end.twist)

    @staticmethod
    def _relative(origin, pose, twist) -> np.ndarray:
        c, s = math.cos(origin[2]), math.sin(origin[2])
        dx, dy = pose[0] - origin[0], pose[1] - origin[1]
        return np.array([c * dx + s * dy, -s * dx + c * dy, wrap_angle(pose[2] - origin[2]), *twist])

    def _update(self, prev: _Observation, obs: _Observation) -> bool:
        """Learn from the motion between two observations; False if nothing was learned."""
        duration = obs.now - prev.now
        # what fired after the previous observation: newer than it knew, not before it (a firing
        # at the observation's own instant, after it was taken, belongs to the window)
        window = {limb: max(t - prev.now, 0.0) for limb, t in obs.fired.items()
                  if prev.now - 1e-9 <= t <= obs.now and t > prev.fired.get(limb, -math.inf) + 1e-9}
        # columns: the limbs fired in the window or still relaxing (the others do not show), and
        # the torque if it is estimated (it turns the robot whether a limb moved or not)
        columns = sorted({LIMB_IDS[limb] for limb in window}
                         | {LIMB_IDS[limb] for limb, t in prev.fired.items() if prev.now - t < RELAXING_S})
        if self.torque_sd > 0.0:
            columns += [_TORQUE, _TORQUE + 1]       # the torque then and now
        if not columns:
            return False                            # nothing fired or relaxing: the strengths do not show
        state, cov = self._augmented(duration)
        base = self._predict(state, prev, window, duration)
        if base is None:
            return False
        jac = np.zeros((6, state.size))
        for col in columns:
            step = STEP if col < _N_LIMBS else self.torque_sd
            shifted = state.copy()
            shifted[col] += step
            moved = self._predict(shifted, prev, window, duration)
            if moved is None:
                return False
            jac[:, col] = (moved - base) / step
        residual = self._relative(prev.pose, obs.pose, obs.twist) - base
        residual[2] = wrap_angle(residual[2])
        cov += np.diag([self.drift_var] * _N_LIMBS + [0.0, 0.0])
        innovation = jac @ cov @ jac.T + np.diag(self.noise_var)
        gain = cov @ jac.T @ np.linalg.inv(innovation)
        state = state + gain @ residual
        cov = (np.eye(state.size) - gain @ jac) @ cov
        keep = [*range(_N_LIMBS), _TORQUE + 1]     # the torque then is marginalised out
        state, cov = state[keep], cov[np.ix_(keep, keep)]
        lo, hi = np.log(BOUNDS)
        state[:_N_LIMBS] = np.clip(state[:_N_LIMBS], lo, hi)
        bound = TORQUE_BOUND_SD * self.torque_sd
        state[_TORQUE] = np.clip(state[_TORQUE], -bound, bound)
        self.state = state
        self.cov = 0.5 * (cov + cov.T)
        self.updates += 1
        self.last_residual = residual
        return True
