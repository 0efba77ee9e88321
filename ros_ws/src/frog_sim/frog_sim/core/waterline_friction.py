"""Rate-independent friction at the waterline, lumped on the rigid body (translation and yaw).

The frog floats with its body through the free surface. Where the surface meets the body
(the contact line along the waterline), contact-angle hysteresis resists the line's motion
with a force per unit length ``gamma (cos theta_r - cos theta_a)`` that does not depend on
the speed (de Gennes, *Rev. Mod. Phys.* 57, 1985, sec. IV; for floating bodies, the
"static friction" of small floating objects). Neither the quadratic drag of eq. 1-2 nor
the linear damping of :mod:`~frog_sim.core.body_damping` holds such a force: both vanish
with the speed, so the model's turn after a kick fades out over seconds and carries into
the next periods, while the robot's stops within the period (the hardware runs: the heading
after a single-side kick is flat from about 0.8 s on, and in a sustained turn the model,
not the robot, gains turn period after period).

One coefficient, the friction per unit length of waterline ``f`` [N/m], acting normal to
the contact line where it moves normal to itself, gives both for the square body of side
``L`` (the limbs are under water): a translation along a body axis moves two sides, each
``f L`` (``F_c = 2 f L``); a rotation moves each side's halves in opposite directions,
``int f |s| ds = f L^2 / 4`` per side (``N_c = f L^2``). Lumped on the rigid body as
:mod:`~frog_sim.core.body_damping` lumps its damping (the translation taken isotropic, exact
along the body axes, where the frog swims): a force against the centre-of-mass velocity
``V`` and a torque against the yaw rate ``r``::

    F = -F_c tanh(|V| / v_s) V / |V|,      N = -N_c tanh(r / r_s)

(Coulomb friction, regularised below ``v_s`` = 1 mm/s and ``r_s`` = 0.01 rad/s so that the
explicit step never reverses the motion it brakes), spread over the nodes by mass,
``f_i = m_i F / M + m_i N perp(r_i) / I``: exactly F and N in total, power ``F . V + N r``
<= 0 (tested). ``V`` and ``r`` are the rigid-body velocities of eq. 10-12 from the nodes'
linear and angular momentum, as in :mod:`~frog_sim.core.body_damping`.

Explicit in the integrator (evaluated at the start of each step, like the linear damping):
its largest rate, at the regularisation, ``N_c / (r_s I)`` and ``F_c / (v_s M)`` (about 5
and 1 1/s for the calibrated frog) times dt (2 ms) is ~1e-2, far inside the explicit
stability bound of 2.
"""
from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import njit

from .element_sets import register_explicit_term
from .lumped_wrench import rigid_motion, spread_wrench


def waterline_friction_coefficients(friction_per_length: float, side_length: float) -> tuple[float, float]:
    """(F_c [N], N_c [N m]) of a square waterline of side ``side_length`` [m] with contact-line
    friction ``friction_per_length`` [N/m]: ``(2 f L, f L^2)`` (module doc).

    Examples
    --------
    >>> [round(c, 9) for c in waterline_friction_coefficients(0.01, 0.09)]
    [0.0018, 8.1e-05]
    """
    f, side = float(friction_per_length), float(side_length)
    return 2.0 * f * side, f * side * side


#: Below these speeds the friction falls off linearly (regularised Coulomb friction).
SPEED_SCALE = 1e-3       # [m/s]
YAW_RATE_SCALE = 0.01    # [rad/s]


@njit(cache=True, error_model='numpy')
def waterline_friction_force(x, v, mass, translation, yaw, out):
    """Nodal forces (2N,) [N] of the waterline friction into ``out``; returns the power [W].

    Parameters
    ----------
    x, v : ndarray, shape (2N,)
        Positions [m] and velocities [m/s] (x0, y0, x1, ...).
    mass : ndarray, shape (N,)
        Nodal masses [kg] (eq. 4).
    translation : float
        F_c, the friction force against the centre-of-mass velocity [N].
    yaw : float
        N_c, the friction torque against the yaw rate [N m].
    """
    mt, cx, cy, vx, vy, inertia, r = rigid_motion(x, v, mass)
    speed = np.sqrt(vx * vx + vy * vy)
    # tanh(s / v_s) / s -> 1 / v_s at rest: no division by zero
    k = translation * (np.tanh(speed / SPEED_SCALE) / speed if speed > 1e-12 * SPEED_SCALE else 1.0 / SPEED_SCALE)
    fx = -k * vx
    fy = -k * vy
    torque = -yaw * np.tanh(r / YAW_RATE_SCALE)
    spread_wrench(x, mass, mt, cx, cy, inertia, fx, fy, torque, out)
    return fx * vx + fy * vy + torque * r


def waterline_friction(x, v, mass, translation=0.0, yaw=0.0) -> tuple[np.ndarray, float]:
    """:func:`waterline_friction_force` as a function: (forces (2N,) [N], power [W])."""
    out = np.zeros(np.asarray(x).size)
    power = waterline_friction_force(np.ascontiguousarray(x, dtype=float), np.ascontiguousarray(v, dtype=float),
                                     np.ascontiguousarray(mass, dtype=float), float(translation), float(yaw), out)
    return out, float(power)


WaterlineFrictionTerm = namedtuple('WaterlineFrictionTerm', 'mass coefficients')
WaterlineFrictionTerm.__doc__ = """The waterline friction as an explicit integrator term. Its one element
touches every DOF (DOF map ``arange(2N)``): nodal masses (N,) [kg] and (F_c [N], N_c [N m])
(2,); zero coefficients switch it off."""


@njit(cache=True, inline='always', error_model='numpy')
def waterline_friction_term(term, m, xe, ve, force):
    """Explicit-term kernel of :class:`WaterlineFrictionTerm`: the force at the start of the step."""
    c = term.coefficients
    if c[0] == 0.0 and c[1] == 0.0:
        return False
    waterline_friction_force(xe, ve, term.mass, c[0], c[1], force)
    return True


register_explicit_term(WaterlineFrictionTerm, waterline_friction_term)
