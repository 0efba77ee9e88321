"""Tank calibration recovers a known (tilted, shifted) camera pose from rendered board images."""
import numpy as np
import pytest

from frog_vision.core.camera_model import CameraModel
from frog_vision.core.detection import DetectorSettings, TagDetector
from frog_vision.core.renderer import RenderSettings, TankRenderer
from frog_vision.core.tank_calibration import Board, BoardTag, CameraPose, TankCalibration, calibrate_tank

DISTORTED = CameraModel(640, 480, [[612.0, 0.0, 322.0], [0.0, 611.0, 236.0], [0.0, 0.0, 1.0]],
                        [-0.08, 0.03, 0.0005, -0.0008, 0.0])


@pytest.mark.parametrize("cam", [CameraModel.realsense_640x480(), DISTORTED])
def test_recovers_known_camera_pose(cam, tmp_path):
    truth = CameraPose.overhead(0.82, x=-0.01, y=-0.02, tilt_x=np.radians(3.0), tilt_y=np.radians(1.5),
                                yaw=np.radians(4.0))
    board = Board.from_yaml()
    r = TankRenderer(cam, truth, RenderSettings(noise_sigma=3.0), board=board)
    img = r.render(np.array([0.0, 0.0, 0.3]))          # the robot in the middle, as in use
    dets = TagDetector(DetectorSettings(family=board.family, tag_ids=())).detect(img)
    assert sorted(d.tag_id for d in dets) == [0, 1, 2, 3, 4, 5]
    cal = calibrate_tank(cam, [dets], board, "default")
    assert np.linalg.norm(cal.pose.position - truth.position) < 3e-3          # 3 mm
    assert abs(np.degrees(cal.pose.tilt - truth.tilt)) < 0.1                  # tilt within 0.1 deg
    rot_err = np.degrees(np.arccos((np.trace(cal.pose.rotation.T @ truth.rotation) - 1) / 2))
    assert rot_err < 0.15
    assert cal.reprojection_rms_px < 0.3
    # a point on the tank plane maps to the same place through both poses
    uv = truth.project(cam, [[0.1, 0.2, 0.0]])
    assert np.allclose(cal.pose.pixels_to_plane(cam, uv), [[0.1, 0.2]], atol=5e-4)
    path = tmp_path / "tank.yaml"
    cal.to_yaml(path)
    back = TankCalibration.from_yaml(path)
    assert np.allclose(back.pose.rotation, cal.pose.rotation) and back.reprojection_rms_px == cal.reprojection_rms_px


def test_too_few_tags_and_bad_files(tmp_path):
    board = Board.from_yaml()
    with pytest.raises(ValueError, match="at least 2 board tags"):
        calibrate_tank(CameraModel.realsense_640x480(), [[]], board)
    with pytest.raises(FileNotFoundError, match="does not exist"):
        Board.from_yaml(tmp_path / "none.yaml")
    p = tmp_path / "b.yaml"
    p.write_text("family: tag36h11\ntags: [{id: 1, x: 0}]\n")
    with pytest.raises(ValueError, match="id, size, x, y"):
        Board.from_yaml(p)
    with pytest.raises(ValueError, match="not unique"):
        Board("tag36h11", (BoardTag(1, 0.05, 0, 0), BoardTag(1, 0.05, 1, 0)))
    with pytest.raises(FileNotFoundError):
        TankCalibration.from_yaml(tmp_path / "nope.yaml")


def test_board_yaml_round_trips(tmp_path):
    board = Board.from_yaml()
    board.to_yaml(tmp_path / "b.yaml")
    assert Board.from_yaml(tmp_path / "b.yaml") == board
