"""Parameter tables shared by the vision nodes (one definition per setting)."""
from soft_robot_common import Param

TAG_PARAMS = [
    Param("tag_family", "tagStandard41h12", "AprilTag family of the robot's tag",
          choices=("tagStandard41h12", "tag36h11", "tag25h9", "tag16h5", "tagStandard52h13",
                   "tagCircle21h7", "tagCircle49h12", "tagCustom48h12")),
    Param("tag_id", 47, "id of the robot's tag (other ids are ignored)", min=0, max=100000),
    Param("tag_size", 0.047, "edge of the tag's detected square [m]", min=0.005, max=1.0),
    Param("tag_height", 0.0, "height of the tag face above the board plane z = 0 [m]", min=-0.5, max=0.5),
]
CAMERA_PARAMS = [
    Param("camera_info_file", "", "camera_calibration YAML of the camera; empty = the RealSense "
          "640x480 default (camera_sim, camera_node) or the camera_info topic (tracker)"),
    Param("tank_calibration_file", "", "tank calibration YAML (frog-vision calibrate-tank); empty = "
          "the default camera pose 0.8 m over the tank centre"),
]
