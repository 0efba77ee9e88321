"""Trajectory following (Algorithm 3) and the built-in curves."""
import numpy as np
import pytest

from softkin_fk.core.forward import ForwardSolver
from softkin_fk.core.inverse import solve_ik
from softkin_fk.core.models import build_tendon_finger
from softkin_fk.core.curves import workspace_region
from softkin_fk.core.trajectory import (curve_flame, curve_L, follow_trajectory, read_waypoints_csv,
                                        sample_configuration_space)


def test_builtin_curves_have_documented_size_and_plane():
    """Dimensions as documented in core/curves.py (placed in the resolution-2 workspace)."""
    L, F = curve_L(), curve_flame()
    assert L.shape == (55, 3) and F.shape == (85, 3)
    assert np.allclose(L[:, 2], 0.0125) and np.allclose(F[:, 2], 0.0125)
    assert np.allclose(F[0], F[-1])                       # closed outline
    steps = np.linalg.norm(np.diff(L, axis=0), axis=1)
    # uniform in arc length: all steps equal except the chord across the corner
    assert np.sum(~np.isclose(steps, np.median(steps), rtol=1e-9)) == 1
    assert np.allclose(L[[0, -1]], [[0.098, 0.0625, 0.0125], [0.105, 0.0535, 0.0125]])
    assert np.min(np.linalg.norm(L[:, :2] - [0.098, 0.0535], axis=1)) < steps.max()  # passes the corner
    assert np.ptp(F[:, 0]) == pytest.approx(0.006, abs=1e-5) and np.ptp(F[:, 1]) == pytest.approx(0.0094, abs=2e-5)
    assert (F[:, :2].max(0) + F[:, :2].min(0)) / 2 == pytest.approx([0.099, 0.0575], abs=1e-5)


def test_workspace_region_of_a_linear_map():
    """A linear actuation-to-tip map on [0, 1]^3 has a hexagon (zonotope) as its image: area
    sum |det(g_i, g_j)| = 2 cm^2; its largest inscribed circle (radius 7.07 mm, half the width
    across the g3 edges) sits at the centre."""
    g = np.array([[0.01, 0.0], [0.0, 0.01], [0.005, 0.005]])
    ax = np.linspace(0, 1, 3)
    A = np.array(np.meshgrid(ax, ax, ax, indexing='ij')).reshape(3, -1).T
    rng = np.random.default_rng(0)
    A = A[rng.permutation(len(A))]                        # any sample order
    W = workspace_region(A, A @ g, pixel=1e-4)
    assert W.inside.sum() * 1e-8 == pytest.approx(2e-4, rel=0.03)
    r, c = W.largest_inscribed_circle()
    assert r == pytest.approx(0.01 / np.sqrt(2), abs=2e-4)
    assert np.linalg.norm(c - [0.0075, 0.0075]) < 1e-3
    assert W.margin(np.array([[0.0075, 0.0075], [0.03, 0.0]])) == pytest.approx([0.01 / np.sqrt(2), 0.0], abs=2e-4)


def test_csv_waypoints(tmp_path):
    p = tmp_path / 'w.csv'
    p.write_text('x,y\n100,50\n101,51.5\n')
    w = read_waypoints_csv(str(p), scale=1e-3)
    assert np.allclose(w, [[0.1, 0.05, 0.0125], [0.101, 0.0515, 0.0125]])
    p.write_text('1\n')
    with pytest.raises(ValueError, match='columns'):
        read_waypoints_csv(str(p))


@pytest.mark.slow
def test_path_partly_outside_workspace_stays_continuous_and_reachable():
    """Waypoints from FK of known actuations are reached within lambda; the path then leaves
    the workspace (beyond the straight finger's tip): those waypoints are reported unreached
    and the achieved path stays continuous (no jump larger than twice the waypoint spacing)."""
    mesh = build_tendon_finger(resolution=1)
    fs = ForwardSolver(mesh)
    cs = sample_configuration_space(fs, 2)
    a, b = np.array([0.97, 0.98, 0.97]), np.array([0.92, 0.96, 0.95])
    inside = np.array([fs.solve(a + t * (b - a), tol=1e-10).marker(mesh) for t in np.linspace(0, 1, 4)])
    end = inside[0]
    outside = end + np.linspace(1, 3, 3)[:, None] * np.array([0.004, -0.004, 0.0])  # towards/under the rest tip
    P = np.vstack([inside[::-1], outside])
    tr = follow_trajectory(fs, P, cs, direction='gauss-newton')
    assert np.all(tr.errors[:4] <= 0.2e-3)
    assert not np.all(tr.reached_flags[4:])
    spacing = np.linalg.norm(np.diff(P, axis=0), axis=1).max()
    assert np.linalg.norm(np.diff(tr.reached, axis=0), axis=1).max() <= 2 * spacing


@pytest.mark.slow
def test_builtin_curves_reached_at_default_resolution():
    """The waypoints of each curve nearest to the workspace boundary (L: its start; flame: #19),
    the L's end and the flame's lowest point are reached within lambda = 0.2 mm by the default
    (resolution-2) finger, each by an independent IK solve from the middle of the actuation box
    (the full check on every 5th waypoint is ``softkin workspace --ik-every 5``)."""
    mesh = build_tendon_finger()
    fs = ForwardSolver(mesh)
    mid = np.array([np.mean(a.bounds) for a in mesh.actuators])
    L, F = curve_L(), curve_flame()
    for p in (L[0], L[-1], F[19], F[63]):
        r = solve_ik(fs, p, initial=mid, direction='gauss-newton')
        assert r.error <= 0.2e-3, (p, r.error)


@pytest.mark.parametrize("jacobian", ["central", "implicit"])
@pytest.mark.slow
def test_L_start_is_reached_from_the_configuration_space(jacobian):
    """Algorithm 3 on the first 'L' waypoints at the default resolution. From the nearest
    sample the IK used to stall at 0.39 mm on waypoint 0 (a cable at its rest length, s = 1,
    can sit slack or taut); the retry from a fresh FK solve, then with that cable pulled just
    taut, must reach every waypoint within lambda."""
    fs = ForwardSolver(build_tendon_finger())
    cs = sample_configuration_space(fs, 5)
    tr = follow_trajectory(fs, curve_L()[:4], cs, direction='gauss-newton', jacobian=jacobian)
    assert tr.reached_flags.all(), tr.errors
    assert tr.errors.max() <= 0.2e-3
