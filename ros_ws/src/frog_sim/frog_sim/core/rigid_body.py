"""Rigid-body approximation of the rod network (paper eq. 10-13).

State ``q = [x_c, y_c, theta, xdot_c, ydot_c, thetadot]`` (paper, "Data Collection").

* eq. 10: centre of mass ``x_c = sum m_i x_i / M_T`` (and its velocity likewise). The
  masses are the revised lumped masses of eq. 4 (structural + added mass), the ones
  that carry the momentum in the integrator.
* eq. 11 (heading). As printed, ``theta = 1/N sum acos((x_i^O x x_i^REF) / (|x_i^O||x_i^REF|))``
  is not a signed angle: acos of the normalised *cross* product returns pi/2 - |angle|
  for small rotations and cannot tell left from right turns. **Resolution:** we use the
  signed, mass-weighted least-squares rotation that maps the reference pose onto the
  current pose (2D Procrustes/Kabsch)::

      theta = atan2( sum m_i (x_i^REF x x_i^O),  sum m_i (x_i^REF . x_i^O) )

  For a rigid rotation by alpha every node gives the same angle and theta = alpha
  exactly (the intent of eq. 11); it is counter-clockwise positive (REP-103) and is
  unwrapped in time by the caller (:class:`HeadingUnwrapper`).
* eq. 12 (yaw rate): ``thetadot = sum m_i (x_i^O x (xdot_i - xdot_c)) / |x_i^O|^2 / M_T``.
  The paper's first form is used (mass-weighted; its second form drops m_i). We
  subtract the COM velocity so that a pure translation gives zero yaw rate (with the
  1/|x^O|^2 weights the COM term does not cancel by itself).
* eq. 13 (inverse): ``xdot_i = xdot_c + thetadot (-y_i^O, x_i^O)``; with eq. 12 this
  round-trips exactly.

Positions are in the world frame ``tank`` (x forward at heading 0). Body-frame
velocities (``frog`` frame, x forward, y left) are ``R(theta)^T xdot_c``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class RigidBodyState:
    """Rigid-body summary of the rod network at one time.

    Attributes
    ----------
    time : float
        [s]
    com : ndarray, shape (2,)
        Centre of mass in the world frame [m] (eq. 10).
    heading : float
        theta [rad], counter-clockwise, unwrapped (eq. 11, resolved).
    com_velocity : ndarray, shape (2,)
        World-frame COM velocity [m/s].
    yaw_rate : float
        thetadot [rad/s] (eq. 12).
    """

    time: float
    com: np.ndarray
    heading: float
    com_velocity: np.ndarray
    yaw_rate: float

    @property
    def body_velocity(self) -> np.ndarray:
        """COM velocity in the robot frame (forward, left) [m/s]."""
        c, s = np.cos(self.heading), np.sin(self.heading)
        vx, vy = self.com_velocity
        return np.array([c * vx + s * vy, -s * vx + c * vy])

    def as_vector(self) -> np.ndarray:
        """Paper's q = [x_c, y_c, theta, xdot_c, ydot_c, thetadot] (SI)."""
        return np.array([*self.com, self.heading, *self.com_velocity, self.yaw_rate])


def center_of_mass(positions: np.ndarray, mass: np.ndarray) -> np.ndarray:
    """Mass-weighted centre (eq. 10).

    Parameters
    ----------
    positions : ndarray, shape (N, 2)
        [m] (or velocities [m/s] for the COM velocity).
    mass : ndarray, shape (N,)
        [kg]

    Returns
    -------
    ndarray, shape (2,)
    """
    return mass @ positions / mass.sum()


def heading_angle(positions: np.ndarray, reference: np.ndarray, mass: np.ndarray) -> float:
    """Signed least-squares rotation from ``reference`` to ``positions`` (eq. 11, resolved).

    Parameters
    ----------
    positions : ndarray, shape (N, 2)
        Current node positions [m].
    reference : ndarray, shape (N, 2)
        Reference pose with its centre of mass at the origin [m].
    mass : ndarray, shape (N,)

    Returns
    -------
    float
        Angle in (-pi, pi] [rad].
    """
    rel = positions - center_of_mass(positions, mass)
    cross = np.sum(mass * (reference[:, 0] * rel[:, 1] - reference[:, 1] * rel[:, 0]))
    dot = np.sum(mass * (reference[:, 0] * rel[:, 0] + reference[:, 1] * rel[:, 1]))
    return float(np.arctan2(cross, dot))


def yaw_rate(positions: np.ndarray, velocities: np.ndarray, mass: np.ndarray) -> float:
    """Average angular velocity (eq. 12, mass-weighted form, COM velocity removed) [rad/s]."""
    rel = positions - center_of_mass(positions, mass)
    vrel = velocities - center_of_mass(velocities, mass)
    r2 = np.sum(rel * rel, axis=1)
    ok = r2 > 1e-24
    cross = rel[:, 0] * vrel[:, 1] - rel[:, 1] * vrel[:, 0]
    return float(np.sum(mass[ok] * cross[ok] / r2[ok]) / mass.sum())


def nodal_velocities(positions: np.ndarray, mass: np.ndarray, com_velocity, yaw_rate_value: float) -> np.ndarray:
    """Node velocities for a given COM velocity and yaw rate (eq. 13).

    Parameters
    ----------
    positions : ndarray, shape (N, 2)
        [m]
    mass : ndarray, shape (N,)
        [kg] (to locate the centre of mass).
    com_velocity : array-like, shape (2,)
        World-frame COM velocity [m/s].
    yaw_rate_value : float
        [rad/s]

    Returns
    -------
    ndarray, shape (N, 2)
        [m/s]
    """
    com_velocity = np.asarray(com_velocity, dtype=float)
    if com_velocity.shape != (2,) or not np.all(np.isfinite(com_velocity)):
        raise ValueError(f'com_velocity = {com_velocity!r}, expected 2 finite values [m/s]')
    if not np.isfinite(yaw_rate_value):
        raise ValueError(f'yaw rate = {yaw_rate_value!r} rad/s must be finite')
    rel = positions - center_of_mass(positions, mass)
    perp = np.column_stack([-rel[:, 1], rel[:, 0]])
    return com_velocity[None, :] + yaw_rate_value * perp


class HeadingUnwrapper:
    """Keeps the heading continuous (adds multiples of 2 pi across the +-pi cut)."""

    def __init__(self, initial: float = 0.0):
        self._last = float(initial)

    def __call__(self, angle: float) -> float:
        """Unwrapped version of ``angle`` [rad] closest to the previous value."""
        unwrapped = angle + 2 * np.pi * np.round((self._last - angle) / (2 * np.pi))
        self._last = unwrapped
        return unwrapped

    def reset(self, value: float) -> None:
        """Restart unwrapping from ``value``."""
        self._last = float(value)


def rigid_body_state(time, positions, velocities, mass, reference, unwrapper=None) -> RigidBodyState:
    """Full rigid-body state (eq. 10-12) of a node configuration.

    Parameters
    ----------
    time : float
        [s]
    positions, velocities : ndarray, shape (N, 2)
        [m], [m/s]
    mass : ndarray, shape (N,)
        [kg]
    reference : ndarray, shape (N, 2)
        Reference pose centred at its COM [m].
    unwrapper : HeadingUnwrapper, optional
        Makes the heading continuous over successive calls.

    Returns
    -------
    RigidBodyState
    """
    heading = heading_angle(positions, reference, mass)
    if unwrapper is not None:
        heading = unwrapper(heading)
    return RigidBodyState(float(time), center_of_mass(positions, mass), heading,
                          center_of_mass(velocities, mass), yaw_rate(positions, velocities, mass))
