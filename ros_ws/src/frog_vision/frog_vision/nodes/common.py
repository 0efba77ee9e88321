"""Loading the calibration files the nodes name in their parameters."""
from __future__ import annotations

from soft_robot_common import ConfigurationError

from frog_vision.core.camera_model import CameraModel
from frog_vision.core.tank_calibration import CameraPose, TankCalibration

DEFAULT_CAMERA_HEIGHT = 0.8


def load_camera(path: str) -> CameraModel | None:
    if not path:
        return None
    try:
        return CameraModel.from_yaml(path)
    except (OSError, ValueError) as exc:
        raise ConfigurationError(f"camera_info_file: {exc}") from exc


def load_camera_pose(path: str) -> CameraPose:
    if not path:
        return CameraPose.overhead(DEFAULT_CAMERA_HEIGHT)
    try:
        return TankCalibration.from_yaml(path).pose
    except (OSError, ValueError) as exc:
        raise ConfigurationError(f"tank_calibration_file: {exc}") from exc
