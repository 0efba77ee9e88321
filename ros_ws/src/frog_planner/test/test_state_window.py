"""The paper loop's mean state: against numpy, across the +-pi seam, empty and cleared."""
import math

import numpy as np
import pytest

from frog_planner.core.state_window import StateWindow


def test_mean_is_numpys_and_the_heading_is_unwrapped_across_pi():
    rng = np.random.default_rng(4)
    poses = np.column_stack([rng.normal(0.1, 0.01, 9), rng.normal(0.2, 0.01, 9), rng.normal(math.pi, 0.2, 9)])
    twists = rng.normal(0, 0.02, (9, 3))
    w = StateWindow()
    for p, t in zip(poses, twists):
        wrapped = (p[0], p[1], math.remainder(p[2], 2 * math.pi))      # as odometry reports it
        w.add(wrapped, t)
    pose, twist, n = w.mean()
    assert n == 9
    assert pose[:2] == pytest.approx(poses[:, :2].mean(axis=0), abs=1e-12)
    assert math.remainder(pose[2] - poses[:, 2].mean(), 2 * math.pi) == pytest.approx(0, abs=1e-12)
    assert -math.pi <= pose[2] <= math.pi
    assert twist == pytest.approx(twists.mean(axis=0), abs=1e-12)


def test_empty_window_raises_and_clear_forgets():
    w = StateWindow()
    with pytest.raises(ValueError, match="no state"):
        w.mean()
    w.add((1.0, 1.0, 3.0), (0.0, 0.0, 0.0))
    w.clear()
    w.add((0.0, 0.0, -3.0), (0.01, 0.0, 0.0))
    pose, twist, n = w.mean()
    assert n == 1 and pose == pytest.approx([0, 0, -3.0]) and twist[0] == pytest.approx(0.01)
