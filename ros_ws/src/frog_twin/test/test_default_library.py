"""The default motion library is regenerated when the frog model it was made with is not today's."""
import numpy as np

from frog_common.motion_library_file import write_motion_library
from frog_sim.core.model_parameters import FrogParameters
from frog_twin.twin import _library_model_differs


def _library(path, robot: dict):
    n, t = 2, 3
    states = np.zeros((n, 3))
    times = np.arange(t) * 0.1
    transitions = np.zeros((9, n, t, 6))
    converged = np.ones((9, n), dtype=bool)
    return write_motion_library(path, states, times, transitions, converged, {"robot": robot})


def test_a_library_of_todays_model_is_kept(tmp_path):
    assert _library_model_differs(_library(tmp_path / "lib.npz", FrogParameters().as_dict())) == ""


def test_a_library_made_before_the_waterline_friction_is_stale(tmp_path):
    robot = FrogParameters().as_dict()
    now = robot.pop("waterline_friction")
    assert now > 0.0
    stale = _library_model_differs(_library(tmp_path / "lib.npz", robot))
    assert stale == f"waterline_friction = None, now {now!r}"


def test_a_library_of_another_calibration_is_stale(tmp_path):
    robot = dict(FrogParameters().as_dict(), waterline_friction=0.0)
    assert _library_model_differs(_library(tmp_path / "lib.npz", robot)).startswith("waterline_friction = 0.0")
