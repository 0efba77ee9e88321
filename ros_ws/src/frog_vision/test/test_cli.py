"""frog-vision CLI: render -> track round trip, calibrate-tank on rendered board images, bad input."""
import csv

import cv2
import numpy as np
import pytest

from frog_vision.cli import main
from frog_vision.core.camera_model import CameraModel
from frog_vision.core.renderer import RenderSettings, TankRenderer
from frog_vision.core.tank_calibration import CameraPose, TankCalibration


def _rows(path):
    with open(path) as f:
        return list(csv.DictReader(f))


@pytest.mark.slow
def test_render_then_track_round_trip(tmp_path):
    out = tmp_path / "r"
    assert main(["render", "--duration", "2", "-o", str(out), "--png"]) == 0
    truth = _rows(out / "ground_truth.csv")
    assert len(truth) == 60 and (out / "frame_00059.png").is_file()
    # track the PNG frames (lossless; the mp4 is lossy) with the files render wrote
    frames = tmp_path / "frames"
    frames.mkdir()
    for p in sorted(out.glob("frame_*.png")):
        p.rename(frames / p.name)
    assert main(["track", str(frames), "--camera-info", str(out / "camera_info.yaml"), "--tank-calibration",
                 str(out / "tank_calibration.yaml"), "-o", str(tmp_path / "t.csv"),
                 "--plot", str(tmp_path / "t.png")]) == 0
    est = _rows(tmp_path / "t.csv")
    assert len(est) == 60 and all(r["detected"] == "1" for r in est)
    err = [np.hypot(float(e["x_measured"]) - float(t["x"]), float(e["y_measured"]) - float(t["y"]))
           for e, t in zip(est, truth)]
    assert np.mean(err) < 5e-4
    assert (tmp_path / "t.png").stat().st_size > 1000


def test_track_a_video_writes_an_annotated_video(tmp_path):
    out = tmp_path / "r"
    assert main(["render", "--duration", "1", "-o", str(out)]) == 0
    assert main(["track", str(out / "frames.mp4"), "--tank-calibration", str(out / "tank_calibration.yaml"),
                 "-o", str(tmp_path / "t.csv"), "--video", str(tmp_path / "a.mp4")]) == 0
    assert sum(r["detected"] == "1" for r in _rows(tmp_path / "t.csv")) >= 27
    cap = cv2.VideoCapture(str(tmp_path / "a.mp4"))
    assert cap.isOpened() and int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == 30


def test_calibrate_tank_from_board_images(tmp_path):
    cam = CameraModel.realsense_640x480()
    truth = CameraPose.overhead(0.81, 0.005, -0.01, np.radians(2.0), np.radians(-1.0), np.radians(3.0))
    r = TankRenderer(cam, truth, RenderSettings(noise_sigma=3.0))
    paths = []
    for k in range(2):
        p = tmp_path / f"board_{k}.png"
        cv2.imwrite(str(p), r.render(np.array([0.0, 0.05 * k, 0.2])))
        paths.append(str(p))
    cam.to_yaml(tmp_path / "cam.yaml")
    out = tmp_path / "tank.yaml"
    assert main(["calibrate-tank", *paths, "--camera-info", str(tmp_path / "cam.yaml"), "-o", str(out),
                 "--plot", str(tmp_path / "reproj.png")]) == 0
    cal = TankCalibration.from_yaml(out)
    assert np.linalg.norm(cal.pose.position - truth.position) < 2e-3
    assert cal.reprojection_rms_px < 0.3 and len(cal.tag_ids) == 6


@pytest.mark.parametrize("argv,message", [
    (["track", "/nonexistent/video.mp4"], "no such file"),
    (["track", "{tmp}/junk.mp4"], "not a readable video"),
    (["track", "{tmp}", "--tank-calibration", "{tmp}/none.yaml"], "does not exist"),
    (["calibrate-tank", "{tmp}/blank.png"], "at least 2 board tags"),
    (["render", "--trajectory", "{tmp}/bad.csv", "-o", "{tmp}/o"], "column 'heading' is missing"),
])
def test_bad_input_exits_2_naming_it(tmp_path, capsys, argv, message):
    (tmp_path / "junk.mp4").write_bytes(b"no video here" * 50)
    cv2.imwrite(str(tmp_path / "blank.png"), np.full((480, 640, 3), 128, np.uint8))
    (tmp_path / "bad.csv").write_text("t,x,y\n0,0,0\n1,0,0\n")
    argv = [a.format(tmp=tmp_path) for a in argv]
    assert main(argv) == 2
    assert message in capsys.readouterr().err


def test_help_has_examples(capsys):
    with pytest.raises(SystemExit):
        main(["--help"])
    assert "examples:" in capsys.readouterr().out


def test_render_a_recorded_odometry_export(tmp_path):
    # the columns 'frog-log export' writes for nav_msgs/Odometry (flattened field names)
    p = tmp_path / "frog__sim__odom.csv"
    lines = ["log_time_ns,header.stamp.sec,header.stamp.nanosec,header.frame_id,child_frame_id,"
             "pose.pose.position.x,pose.pose.position.y,pose.pose.position.z,pose.pose.orientation.x,"
             "pose.pose.orientation.y,pose.pose.orientation.z,pose.pose.orientation.w,"
             "twist.twist.linear.x,twist.twist.linear.y,twist.twist.angular.z"]
    for k in range(51):
        t = k * 0.02
        h = 0.3 + 0.2 * t
        lines.append(f"0,{int(t)},{int(round((t % 1) * 1e9))},tank,frog,{0.02 * t},{0.01},0,0,0,"
                     f"{np.sin(h / 2)},{np.cos(h / 2)},0.02,0,0.2")
    p.write_text("\n".join(lines) + "\n")
    out = tmp_path / "o"
    assert main(["render", "--trajectory", str(p), "-o", str(out)]) == 0
    truth = _rows(out / "ground_truth.csv")
    assert len(truth) == 30
    assert float(truth[15]["heading"]) == pytest.approx(0.3 + 0.2 * 0.5, abs=1e-6)
    assert float(truth[15]["forward"]) == pytest.approx(0.02)
