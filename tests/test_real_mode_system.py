"""frog-twin's real mode end to end on emulated devices (issue 20).

The "camera" is a real camera_node playing a video the project's renderer made of the robot
at the line path's start; the "robot" is robot_emulator behind a pty opened as a device
path. Pre-flight passes, the planner decides, 'h' lines reach the port, /frog/stop ends the
run within one period, the report is written. Each pre-flight check is broken once.
"""

import csv
import json
import math
import os
import subprocess
import time

import pytest
import yaml

pytestmark = pytest.mark.system
FPS = 15.0
PERIOD = 1.43
#: the emulated robot's IMU reports the heading the tracker sees (there is no simulator here)
EMULATED_IMU = {"frog/sim/odom": "frog/odom"}


def _render(folder, y_of_t, duration, x=0.0):
    folder.mkdir(parents=True, exist_ok=True)
    traj = folder / "traj.csv"
    with open(traj, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["t", "x", "y", "heading"])
        for i in range(int(duration * 10) + 1):
            t = i / 10
            w.writerow([t, x, y_of_t(t), math.pi / 2])
    r = subprocess.run(["frog-vision", "render", "--trajectory", str(traj), "--fps", str(FPS), "--noise", "1",
                        "-o", str(folder)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    return folder


@pytest.fixture(scope="module")
def video(tmp_path_factory):
    # the line path's start (frog-twin places it at x 0, y -0.233, heading +y); slow swim along it
    return _render(tmp_path_factory.mktemp("video"), lambda t: -0.233 + 0.004 * t, 45.0)


def _frog_twin(args, env, timeout):
    return subprocess.Popen(["frog-twin", *map(str, args)], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def _real_args(video, port, library, out, domain, **extra):
    args = ["--robot-port", port, "--camera", video / "frames.mp4", "--camera-info", video / "camera_info.yaml",
            "--tank-calibration", video / "tank_calibration.yaml", "--camera-fps", FPS, "--path", "line",
            "--library", library, "--out", out, "--domain", domain, "--duration", "40"]
    for k, v in extra.items():
        args += [f"--{k.replace('_', '-')}", v]
    return args


def test_real_mode_on_emulated_devices(video, library, launch, ros_domain, tmp_path):
    import rclpy
    from std_msgs.msg import Empty
    link = tmp_path / "robot_tty"
    commands = tmp_path / "robot_commands.csv"
    launch("robot_emulator", params={"link_path": str(link), "command_log": str(commands), "seed": 3},
           remap=EMULATED_IMU)
    deadline = time.monotonic() + 60
    while not link.exists():
        assert time.monotonic() < deadline, "the emulator's pty did not appear"
        time.sleep(0.1)
    out = tmp_path / "real"
    proc = _frog_twin(_real_args(video, link, library, out, ros_domain.domain_id), ros_domain.env, 400)
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=ros_domain.domain_id)
    node = rclpy.create_node("stop_sender", context=ctx)
    pub = node.create_publisher(Empty, "/frog/stop", 10)
    try:
        # decisions are made and 'h' lines reach the port
        deadline = time.monotonic() + 240
        h_lines = []
        while len(h_lines) < 6:          # at most two lines (front, rear) per decision: >= 3 decisions
            if proc.poll() is not None:
                so, se = proc.communicate()
                pytest.fail(f"frog-twin ended early ({proc.returncode}):\n{so[-3000:]}\n{se[-3000:]}")
            assert time.monotonic() < deadline, "fewer than 6 'h' lines reached the port"
            time.sleep(0.5)
            if commands.exists():
                with open(commands) as fh:
                    h_lines = [r for r in csv.DictReader(fh) if r["line"].startswith("h ")]
        t_stop = time.time()
        for _ in range(5):
            pub.publish(Empty())
            time.sleep(0.05)
        stdout, stderr = proc.communicate(timeout=180)
    finally:
        if proc.poll() is None:
            proc.kill()
        node.destroy_node()
        rclpy.shutdown(context=ctx)
    (tmp_path / "frog_twin.out").write_text(stdout + "\n--- stderr ---\n" + stderr)
    assert proc.returncode == 0, stdout[-3000:] + stderr[-3000:]
    assert "no --tag-offset file" in stderr
    assert "stopped (stop received on /frog/stop)" in stdout, stdout[-2000:]
    for name in ("camera", "calibration", "tag", "link", "library", "start"):
        assert f"pre-flight {name}" in stdout, stdout
    # nothing was heated after the stop, beyond one period
    with open(commands) as fh:
        rows = list(csv.DictReader(fh))
    h_after = [float(r["wall_time_s"]) for r in rows if r["line"].startswith("h ")
               and float(r["wall_time_s"]) > t_stop + PERIOD]
    assert not h_after, (t_stop, h_after)
    (m,) = json.loads((out / "metrics.json").read_text())
    assert m["mode"] == "real" and m["stop_reason"] == "stop received on /frog/stop"
    assert m["decisions"] >= 3 and m["latency_decision_to_serial"]["n"] >= 3, m
    assert all(c["ok"] for c in m["preflight"])
    for f, size in (("line.png", 20_000), ("line.mp4", 10_000), ("line.json", 1000)):
        assert (out / f).stat().st_size > size, f
    assert list((out / "line" / "recording").glob("*.mcap"))


def _preflight_failure(args, env):
    r = subprocess.run(["frog-twin", *map(str, args)], env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 2, r.stdout[-2000:] + r.stderr[-2000:]
    assert "pre-flight failed, nothing was actuated" in r.stderr, r.stderr[-2000:]
    return r.stderr


def test_preflight_no_tag(library, launch, ros_domain, tmp_path):
    empty = _render(tmp_path / "empty", lambda t: 0.0, 12.0, x=3.0)     # the robot far outside the view
    link = tmp_path / "robot_tty"
    launch("robot_emulator", params={"link_path": str(link)}, remap=EMULATED_IMU)
    while not link.exists():
        time.sleep(0.1)
    err = _preflight_failure(_real_args(empty, link, library, tmp_path / "o", ros_domain.domain_id,
                                        preflight_timeout=8), ros_domain.env)
    assert "tag not detected" in err


def test_preflight_wrong_image_size(video, library, launch, ros_domain, tmp_path):
    tank = yaml.safe_load((video / "tank_calibration.yaml").read_text())
    tank["image_size"] = [1280, 720]
    bad = tmp_path / "video"
    bad.mkdir()
    for f in ("frames.mp4", "camera_info.yaml"):
        os.symlink(video / f, bad / f)
    (bad / "tank_calibration.yaml").write_text(yaml.safe_dump(tank))
    link = tmp_path / "robot_tty"
    launch("robot_emulator", params={"link_path": str(link)}, remap=EMULATED_IMU)
    while not link.exists():
        time.sleep(0.1)
    err = _preflight_failure(_real_args(bad, link, library, tmp_path / "o", ros_domain.domain_id,
                                        preflight_timeout=8), ros_domain.env)
    assert "is for 1280x720 images but the camera delivers 640x480 frames" in err


def test_preflight_silent_port(video, library, ros_domain, serial_pair, tmp_path):
    _, device = serial_pair                 # a pty nobody answers on
    err = _preflight_failure(_real_args(video, device, library, tmp_path / "o", ros_domain.domain_id,
                                        preflight_timeout=8), ros_domain.env)
    assert "'Central: Q' line(s)" in err or "link to" in err
