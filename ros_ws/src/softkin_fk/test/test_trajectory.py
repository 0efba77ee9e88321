"""Trajectory following (Algorithm 3) and the built-in curves."""
import numpy as np
import pytest

from softkin_fk.core.forward import ForwardSolver
from softkin_fk.core.models import build_tendon_finger
from softkin_fk.core.trajectory import (curve_flame, curve_L, follow_trajectory, read_waypoints_csv,
                                        sample_configuration_space)


def test_builtin_curves_have_documented_size_and_plane():
    L, F = curve_L(), curve_flame()
    assert L.shape == (55, 3) and F.shape == (85, 3)
    assert np.allclose(L[:, 2], 0.0125) and np.allclose(F[:, 2], 0.0125)
    assert np.allclose(F[0], F[-1])                       # closed outline
    steps = np.linalg.norm(np.diff(L, axis=0), axis=1)
    # uniform in arc length: all steps equal except the chord across the corner
    assert np.sum(~np.isclose(steps, np.median(steps), rtol=1e-9)) == 1
    assert np.linalg.norm(L[-1] - L[0]) == pytest.approx(np.hypot(0.006, 0.007))


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
