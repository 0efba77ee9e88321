"""Tracking accuracy on rendered sequences of frog_sim's simulated frog swimming and turning,
against the renderer's exact ground truth (issue 12's verification; table: bench/vision_accuracy.py)."""
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))

from frog_vision.core.camera_model import CameraModel  # noqa: E402
from frog_vision.core.renderer import RenderSettings, TankRenderer  # noqa: E402
from frog_vision.core.tank_calibration import CameraPose  # noqa: E402
from frog_vision.core.tracker import Tracker  # noqa: E402
from vision_sequences import run_simulated, simulated_sequence  # noqa: E402

CAMERA = CameraModel.realsense_640x480()
POSE = CameraPose.overhead(0.8)


@pytest.fixture(scope="module")
def swim():
    return simulated_sequence(duration=8.0)


def _run(swim, occlusion=(), **render):
    r = TankRenderer(CAMERA, POSE, RenderSettings(**render))
    return run_simulated(r, Tracker(CAMERA, POSE), *swim, occlusion=occlusion)


def test_the_sequence_swims_and_turns(swim):
    truth, _ = swim
    assert np.ptp(truth.pose[:, 0]) + np.ptp(truth.pose[:, 1]) > 0.05
    assert np.ptp(np.unwrap(truth.pose[:, 2])) > np.radians(15)
    assert truth.twist[:, 0].max() > 0.02


def test_clean_frames_at_the_authors_geometry(swim):
    m = _run(swim, noise_sigma=2.0).metrics()
    assert m["detection_rate"] >= 0.99
    assert m["position_mean_mm"] <= 1.0 and m["heading_mean_deg"] <= 0.5


def test_filter_beats_raw_differences_5x_at_the_authors_noise(swim):
    m = _run(swim, noise_sigma=5.0, corner_jitter_px=0.2).metrics()
    assert m["position_mean_mm"] <= 1.0
    assert m["velocity_ratio"] >= 5.0, m
    assert m["yaw_rate_ratio"] >= 5.0, m


def test_recovers_within_3_frames_after_1_s_hidden(swim):
    res = _run(swim, occlusion=[(3.0, 4.0)], noise_sigma=3.0)
    assert not res.detected[res.occluded].any()
    assert res.frames_to_recover() <= 3
