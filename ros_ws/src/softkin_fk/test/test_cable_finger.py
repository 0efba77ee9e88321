"""Cable actuation on the 3-tendon finger: monotonicity and the constant-curvature model."""
import numpy as np
import pytest

from softkin_fk.core.forward import ForwardSolver
from softkin_fk.core.models import FINGER, build_tendon_finger

MM = 1e-3


@pytest.fixture(scope='module')
def finger():
    mesh = build_tendon_finger(resolution=1)
    return mesh, ForwardSolver(mesh)


def tip_angle(mesh, x):
    """Rotation (rad) of the finger's end face about z (0 at rest, > 0 bending towards +y)."""
    v = mesh.vertices
    face = np.flatnonzero(np.isclose(v[:, 0], FINGER['length'] * MM) & np.isclose(v[:, 2], 12.5 * MM))
    top, bot = face[np.argmax(v[face, 1])], face[np.argmin(v[face, 1])]
    return np.arctan2(x[bot, 0] - x[top, 0], x[top, 1] - x[bot, 1])


def cable_gap_length(mesh, x, name):
    g = mesh.group(name)
    mult = mesh.actuators[mesh.actuator_index(name)].segment_multiplicity
    return np.linalg.norm(x[g.elements[:, 1]] - x[g.elements[:, 0]], axis=1).sum() / mult


def test_tip_angle_grows_monotonically_with_cable_shortening(finger):
    mesh, fs = finger
    lo = mesh.actuators[2].bounds[0]
    angles = [tip_angle(mesh, fs.solve([1, 1, s], tol=1e-8).positions) for s in np.linspace(1.0, lo, 6)]
    assert angles[0] == pytest.approx(0.0, abs=1e-9)
    assert np.all(np.diff(angles) > np.deg2rad(1.0))


def test_small_uniform_bending_matches_constant_curvature(finger):
    """Webster & Jones (2010): tendons at distance d from the neutral axis shortened by dl in
    total bend the section by theta = dl / d. Pulling the three cables by the same length
    closes all six equal, evenly spaced slots alike (uniform bending). The cables run at
    y = 25 mm, the neutral axis is the spine's mid-plane (y = 2.5 mm): d = 22.5 mm. The tip's
    lift is compared with the arc of curvature theta / 90 mm over the slotted section
    (x = 10-100 mm) followed by the straight 20 mm tip. Tolerances: 5 % on the angle and on
    the lift."""
    mesh, fs = finger
    d = (FINGER['cable_heights'][2] - FINGER['spine'] / 2) * MM
    L = np.array([a.total_length for a in mesh.actuators])
    l0 = sum(cable_gap_length(mesh, mesh.vertices, f'cable_{j}') for j in range(3))
    tip0 = mesh.vertices[mesh.markers['tip']]
    for pull in (0.1e-3, 0.2e-3, 0.4e-3):
        x = fs.solve(1 - pull / L, tol=1e-9).positions
        dl = l0 - sum(cable_gap_length(mesh, x, f'cable_{j}') for j in range(3))  # achieved (m)
        theta_cc = dl / d
        theta = tip_angle(mesh, x)
        assert theta == pytest.approx(theta_cc, rel=0.05)
        kappa = theta_cc / (90 * MM)
        lift_cc = (1 - np.cos(theta_cc)) / kappa + 20 * MM * np.sin(theta_cc)
        lift = x[mesh.markers['tip'], 1] - tip0[1]
        assert lift == pytest.approx(lift_cc, rel=0.05)


def test_cable_constraint_met_when_enforced(finger):
    """With enforce_constraints the achieved gap shortening equals (1 - s) L (eq. 6)."""
    mesh, fs = finger
    s = 0.95
    res = fs.solve([1, 1, s], tol=1e-8, enforce_constraints=True, constraint_tol=1e-5)
    l0 = cable_gap_length(mesh, mesh.vertices, 'cable_2')
    dl = l0 - cable_gap_length(mesh, res.positions, 'cable_2')
    assert dl == pytest.approx((1 - s) * mesh.actuators[2].total_length, rel=1e-3)


def test_unpulled_cables_stay_slack_and_knuckles_bend_independently(finger):
    """Pulling only the tip knuckle's cable bends the tip knuckle; the proximal knuckles
    (x < 70 mm) move by less than a tenth of the tip's displacement (only the reaction at the
    shared slot wall couples them)."""
    mesh, fs = finger
    res = fs.solve([1, 1, 0.95], tol=1e-9)
    assert not res.active[0] and not res.active[1] and res.active[2]
    assert np.isnan(res.actuator_totals[0])
    prox = mesh.vertices[:, 0] < 70 * MM
    tip_move = np.linalg.norm(res.marker(mesh) - mesh.vertices[mesh.markers['tip']])
    assert tip_move > 5 * MM
    assert np.linalg.norm(res.positions[prox] - mesh.vertices[prox], axis=1).max() < 0.1 * tip_move
