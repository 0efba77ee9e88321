"""A slowly varying yaw torque on the swimming frog: the tank's disturbances.

Replayed open loop from each decision's measured state, the simulator's heading change
per period differs from the robot's by about 4 deg (sd), and the differences of
consecutive periods are correlated (hardware runs: 0.63 at one period, 0.28 at two, about
0 at three), which a kick that varies from one firing to the next (white per period) cannot
give. What acts over seconds on a 5 cm body floating in a small tank: the circulation the
robot's own strokes leave in the tank and reflect off its walls, surface films and
draughts, the slow drift of the limbs' asymmetry as the SMA wires heat. Lumped, as
marine-vehicle models treat currents and wave drift (Fossen 2011, sec. 10.3: a first-order
Gauss-Markov process), as a yaw torque ``N(t)`` about the COM that is an Ornstein-Uhlenbeck
process with time constant ``tau`` and stationary sd ``sd``::

    dN = -N / tau dt + sd sqrt(2 / tau) dW

advanced exactly over each interval ``h``: ``N <- a N + sd sqrt(1 - a^2) xi``, ``a = exp(-h /
tau)``; it acts from the frog's first firing on (a frog waiting for its first command
stays put). The torque is spread over the nodes by mass, ``f_i = m_i N perp(r_i) / I`` (``r_i``
from the COM, ``I = sum m_i |r_i|^2``): a pure torque, zero net force. It is off in the
model (the library, the sweeps and the fidelity replays are deterministic); the digital
twin draws it (``sim_node`` ``yaw_disturbance_sd``, ``yaw_disturbance_tau_s``), with values
identified by ``frog-sim disturbance`` from the hardware runs' residuals.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

#: The tank's yaw torque identified on the authors' hardware runs (``frog-sim disturbance``,
#: jointly with the kick spread; frog_twin's test_kick_variability.py checks them): stationary
#: sd [N m] and time constant [s]. The twin's robot draws it; the planner's rollouts estimate it
#: (:class:`~frog_sim.core.limb_identification.LimbIdentification`).
TANK_YAW_TORQUE_SD = 9.2e-5
TANK_YAW_TORQUE_TAU_S = 1.25


class YawDisturbance:
    """The Ornstein-Uhlenbeck yaw torque: ``sd`` [N m], ``tau`` [s], its own random stream."""

    def __init__(self, sd: float, tau: float, seed: int | None = None):
        if not (math.isfinite(sd) and sd >= 0.0):
            raise ValueError(f'yaw disturbance sd = {sd!r} N m must be finite and >= 0')
        if not (math.isfinite(tau) and tau > 0.0):
            raise ValueError(f'yaw disturbance time constant = {tau!r} s must be finite and > 0')
        self.sd = float(sd)
        self.tau = float(tau)
        self.rng = np.random.default_rng(seed)
        self.torque = self.stationary_draw()

    def stationary_draw(self) -> float:
        """A torque from the stationary distribution N(0, sd^2) (e.g. at a reset mid-run)."""
        return float(self.sd * self.rng.standard_normal())

    def advance(self, h: float) -> float:
        """The torque after ``h`` more seconds (exact OU transition); returns it [N m]."""
        a = math.exp(-h / self.tau)
        self.torque = float(a * self.torque + self.sd * math.sqrt(max(0.0, 1.0 - a * a)) * self.rng.standard_normal())
        return self.torque


def torque_forces(x: np.ndarray, mass: np.ndarray, torque: float) -> np.ndarray:
    """Nodal forces (2N,) [N] of a pure torque [N m] about the COM, spread by mass."""
    out = np.empty(np.asarray(x).size)
    torque_forces_into(np.ascontiguousarray(x, dtype=float).ravel(), np.ascontiguousarray(mass, dtype=float),
                       float(torque), out)
    return out


@njit(nogil=True, cache=True)
def torque_forces_into(x, mass, torque, out):
    """:func:`torque_forces` written into ``out`` (2N,): ``f_i = m_i N perp(r_i) / I`` (also
    called inside the compiled rollouts, once per job)."""
    n = mass.shape[0]
    total = 0.0
    cx = 0.0
    cy = 0.0
    for i in range(n):
        total += mass[i]
        cx += mass[i] * x[2 * i]
        cy += mass[i] * x[2 * i + 1]
    cx /= total
    cy /= total
    inertia = 0.0
    for i in range(n):
        rx, ry = x[2 * i] - cx, x[2 * i + 1] - cy
        inertia += mass[i] * (rx * rx + ry * ry)
    scale = torque / inertia
    for i in range(n):
        out[2 * i] = -mass[i] * scale * (x[2 * i + 1] - cy)
        out[2 * i + 1] = mass[i] * scale * (x[2 * i] - cx)
