"""Shared fixtures: the default camera over the tank and a renderer."""
import numpy as np
import pytest

from frog_vision.core.camera_model import CameraModel
from frog_vision.core.renderer import RenderSettings, TankRenderer
from frog_vision.core.tank_calibration import CameraPose


@pytest.fixture
def camera():
    return CameraModel.realsense_640x480()


@pytest.fixture
def camera_pose():
    return CameraPose.overhead(0.8)


@pytest.fixture
def clean_renderer(camera, camera_pose):
    return TankRenderer(camera, camera_pose, RenderSettings(noise_sigma=2.0, exposure=0.0))


@pytest.fixture
def rng():
    return np.random.default_rng(7)
