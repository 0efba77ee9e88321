"""Parameter tables shared by the vision nodes (one definition per setting)."""
from soft_robot_common import Param, params_from_dataclass

from frog_vision.core.renderer import RenderSettings

# the robot's tag: one definition, the renderer's settings (the tracker detects what camera_sim draws)
TAG_PARAMS = params_from_dataclass(RenderSettings, names=("tag_family", "tag_id", "tag_size", "tag_height"))
CAMERA_PARAMS = [
    Param("camera_info_file", "", "camera_calibration YAML of the camera; empty = the RealSense "
          "640x480 default (camera_sim, camera_node) or the camera_info topic (tracker)"),
    Param("tank_calibration_file", "", "tank calibration YAML (frog-vision calibrate-tank); empty = "
          "the default camera pose 0.8 m over the tank centre"),
]
