"""Camera model: projection round trips and the camera_info YAML format."""
import numpy as np
import pytest
import yaml

from frog_vision.core.camera_model import CameraModel

DISTORTED = CameraModel(640, 480, [[600.0, 0.0, 318.0], [0.0, 602.0, 243.0], [0.0, 0.0, 1.0]],
                        [-0.12, 0.05, 0.001, -0.0015, -0.01], camera_name="test_cam")


@pytest.mark.parametrize("cam", [CameraModel.realsense_640x480(), DISTORTED])
def test_project_then_back_project_round_trips(cam, rng):
    pts = np.column_stack([rng.uniform(-0.3, 0.3, 200), rng.uniform(-0.2, 0.2, 200), rng.uniform(0.5, 1.5, 200)])
    uv = cam.project(pts)
    rays = cam.rays(uv)
    # the ray through the pixel points at the original point
    direction = pts / np.linalg.norm(pts, axis=1, keepdims=True)
    assert np.max(np.linalg.norm(rays - direction, axis=1)) < 1e-8
    # and projecting the ray again lands on the same pixel
    assert np.max(np.abs(cam.project(rays) - uv)) < 1e-6


def test_distortion_moves_corner_pixels_and_undistort_undoes_it():
    ideal = CameraModel(640, 480, DISTORTED.K)
    pt = np.array([[0.25, 0.18, 1.0]])
    d, i = DISTORTED.project(pt)[0], ideal.project(pt)[0]
    assert np.linalg.norm(d - i) > 1.5        # barrel distortion pulls corners in
    assert np.allclose(DISTORTED.undistort_pixels([d])[0], i, atol=1e-6)


def test_camera_info_yaml_round_trips(tmp_path):
    path = tmp_path / "cam.yaml"
    DISTORTED.to_yaml(path)
    data = yaml.safe_load(path.read_text())
    # the fields camera_calibration writes
    assert data["camera_matrix"]["rows"] == 3 and data["distortion_model"] == "plumb_bob"
    assert data["projection_matrix"]["cols"] == 4 and len(data["distortion_coefficients"]["data"]) == 5
    back = CameraModel.from_yaml(path)
    assert (back.width, back.height, back.camera_name) == (640, 480, "test_cam")
    for a in ("K", "D", "R", "P"):
        assert np.array_equal(getattr(back, a), getattr(DISTORTED, a))
    info = back.to_camera_info()
    again = CameraModel.from_camera_info(info)
    assert np.array_equal(again.K, DISTORTED.K) and np.array_equal(again.D, DISTORTED.D)


def test_reads_a_camera_calibration_file_written_by_hand(tmp_path):
    p = tmp_path / "ost.yaml"
    p.write_text("""image_width: 640
image_height: 480
camera_name: narrow_stereo
camera_matrix:
  rows: 3
  cols: 3
  data: [615.1, 0, 321.4, 0, 614.9, 238.2, 0, 0, 1]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [0.1, -0.2, 0, 0, 0]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]
projection_matrix:
  rows: 3
  cols: 4
  data: [615.1, 0, 321.4, 0, 0, 614.9, 238.2, 0, 0, 0, 1, 0]
""")
    cam = CameraModel.from_yaml(p)
    assert cam.K[0, 2] == 321.4 and cam.D[1] == -0.2


def test_bad_files_name_the_problem(tmp_path):
    with pytest.raises(FileNotFoundError, match="does not exist"):
        CameraModel.from_yaml(tmp_path / "missing.yaml")
    p = tmp_path / "bad.yaml"
    p.write_text("image_width: 640\nimage_height: 480\n")
    with pytest.raises(ValueError, match="camera_matrix"):
        CameraModel.from_yaml(p)
    p.write_text("image_width: 640\nimage_height: 480\ncamera_matrix: {rows: 3, cols: 3, data: [1, 2]}\n")
    with pytest.raises(ValueError, match="3x3 with 2 values"):
        CameraModel.from_yaml(p)


def test_image_size_mismatch_is_reported():
    cam = CameraModel.realsense_640x480()
    with pytest.raises(ValueError, match="320x240 but the camera model is 640x480"):
        cam.check_image(np.zeros((240, 320, 3), np.uint8))
