"""Parameter tables shared by the vision nodes (one definition per setting)."""
from soft_robot_common import Param, params_from_dataclass

from frog_vision.core.detection import DetectorSettings
from frog_vision.core.pose import PoseSettings
from frog_vision.core.renderer import RenderSettings
from frog_vision.core.state_filter import FilterSettings
from frog_vision.core.tracker import ESTIMATORS

# the robot's tag: one definition, the renderer's settings (the tracker detects what camera_sim draws)
TAG_PARAMS = params_from_dataclass(RenderSettings, names=("tag_family", "tag_id", "tag_size", "tag_height"))
CAMERA_PARAMS = [
    Param("camera_info_file", "", "camera_calibration YAML of the camera; empty = the RealSense "
          "640x480 default (camera_sim, camera_node) or the camera_info topic (tracker)"),
    Param("tank_calibration_file", "", "tank calibration YAML (frog-vision calibrate-tank); empty = "
          "the default camera pose 0.8 m over the tank centre"),
]

# the filter's settings that a user tunes (the gates and initial uncertainties stay the core's)
FILTER_PARAMS = ("accel_noise", "yaw_accel_noise", "kick_window", "kick_delay", "kick_accel_noise",
                 "kick_yaw_accel_noise", "coast_accel_noise", "coast_yaw_accel_noise", "coast_drag_time",
                 "coast_yaw_drag_time", "coast_timeout", "reset_timeout")
TRACKER_PARAMS = TAG_PARAMS + CAMERA_PARAMS + [
    Param("world_frame", "tank", "frame of the poses"),
    Param("body_frame", "frog", "robot frame (child frame of the odometry)"),
] + params_from_dataclass(PoseSettings, names=("offset_x", "offset_y", "offset_yaw")) + params_from_dataclass(
    DetectorSettings, names=("decimate", "threads", "refine_edges")) + [
    Param("search_window", 3.0, "search around the predicted tag, in tag sizes; 0 = whole image", min=0.0, max=50.0),
] + params_from_dataclass(PoseSettings, names=("corner_sigma_px",)) + [
    Param("estimator", "filter", "state from the tag poses: 'filter' (Kalman filter with kick inputs) or "
          "'frame_difference' (the paper's tracker: the raw pose, velocities as differences of consecutive frames)",
          choices=ESTIMATORS),
    Param("kick_topic", "frog/bridge/sent", "limb firings (LimbActivation) fed to the filter as kick inputs; "
          "empty = none"),
] + params_from_dataclass(FilterSettings, names=FILTER_PARAMS) + [
    Param("publish_debug_image", False, "publish frog/tracker/debug_image (annotated frames)", live=True),
    Param("publish_tf", True, "publish the tracked pose on tf as world_frame -> body_frame"),
    Param("frozen_frames", 3, "this many byte-identical frames in a row (the first included) mean a frozen camera: "
          "nothing is published from them until the frames change", min=2, max=1000, live=True),
]


def filter_settings(values: dict) -> FilterSettings:
    """The tracker's filter settings from its parameters (ValueError naming a bad one)."""
    from frog_common.settings import from_params
    return from_params(FilterSettings, {k: values[k] for k in FILTER_PARAMS})


def filter_problem(values: dict) -> str | None:
    """Why a candidate parameter set gives no usable filter settings, or None."""
    try:
        filter_settings(values)
    except ValueError as exc:
        return str(exc)
    return None
