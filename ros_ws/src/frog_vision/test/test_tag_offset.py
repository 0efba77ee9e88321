"""Tag-to-body offset from a synthetic straight swim with a known offset (and the CLI end to end)."""
import csv
import math
import subprocess

import numpy as np
import pytest
import yaml

from frog_vision.core.tag_offset import compose, estimate_tag_offset, invert, read_tag_offset


def straight_swim(offset, duration=30.0, rate=30.0, seed=0, noise=(0.0003, math.radians(0.3))):
    """Tag poses of a body swimming straight (kicks every 1.43 s, yaw wiggles), tag at ``offset``."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration, 1.0 / rate)
    v = 0.02 + 0.012 * np.maximum(0, np.sin(2 * np.pi * t / 1.43)) ** 2
    psi = 0.7 + 0.12 * np.sin(2 * np.pi * t / 2.3) + 0.05 * np.sin(2 * np.pi * t / 0.9 + 1)
    dt = 1.0 / rate
    xy = np.cumsum(np.column_stack([v * np.cos(psi), v * np.sin(psi)]) * dt, axis=0)
    body = np.column_stack([xy, psi])
    tag = compose(body, invert(offset))      # body = tag o offset
    tag[:, :2] += rng.normal(0, noise[0], (len(t), 2))
    tag[:, 2] += rng.normal(0, noise[1], len(t))
    return t, tag


@pytest.mark.parametrize("offset", [(0.0034, 0.0, math.radians(5.6)), (-0.004, 0.003, math.radians(-3.0))])
@pytest.mark.slow
def test_known_offset_is_recovered(offset):
    t, tag = straight_swim(offset)
    r = estimate_tag_offset(t, tag)
    assert abs(r.offset_yaw - offset[2]) < math.radians(0.5) and r.offset_yaw_sd < math.radians(0.5)
    assert abs(r.offset_x - offset[0]) < 0.001 and abs(r.offset_y - offset[1]) < 0.001, r
    assert r.offset_y_sd < 0.002 and r.windows >= 15


def test_turning_log_is_refused():
    t = np.arange(0, 10, 1 / 30)
    tag = np.column_stack([0.01 * np.cos(t), 0.01 * np.sin(t), 2.0 * t])
    with pytest.raises(ValueError, match="straight swim"):
        estimate_tag_offset(t, tag)


@pytest.mark.system
def test_cli_writes_the_file_the_twin_reads(tmp_path):
    offset = (0.0034, 0.002, math.radians(5.6))
    t, tag = straight_swim(offset, seed=3)
    measured = compose(tag, (0.0034, 0.0, 0.0))      # what frog-vision track wrote with its default offset
    f = tmp_path / "track.csv"
    with open(f, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["t", "detected", "x_measured", "y_measured", "heading_measured", "x", "y", "heading"])
        for ti, p in zip(t, measured):
            w.writerow([ti, 1, *p, *p])
    out = tmp_path / "tag_offset.yaml"
    r = subprocess.run(["frog-vision", "tag-offset", str(f), "-o", str(out)], capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0, r.stderr
    params = read_tag_offset(out)
    assert abs(params["offset_yaw"] - offset[2]) < math.radians(0.5)
    assert abs(params["offset_y"] - offset[1]) < 0.001
    assert "spread" in yaml.safe_load(out.read_text())
    bad = subprocess.run(["frog-vision", "tag-offset", str(tmp_path / "nope.csv")], capture_output=True, text=True,
                         timeout=60)
    assert bad.returncode == 2 and "nope.csv" in bad.stderr


POSE_STAMPED = """std_msgs/Header header
geometry_msgs/Pose pose
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
================================================================================
MSG: geometry_msgs/Pose
Point position
Quaternion orientation
================================================================================
MSG: geometry_msgs/Point
float64 x
float64 y
float64 z
================================================================================
MSG: geometry_msgs/Quaternion
float64 x 0
float64 y 0
float64 z 0
float64 w 1
"""


@pytest.mark.system
def test_cli_reads_the_trackers_pose_from_an_mcap(tmp_path):
    from mcap_ros2.writer import Writer
    offset = (0.0034, -0.002, math.radians(-4.0))
    t, tag = straight_swim(offset, seed=5)
    measured = compose(tag, (0.0034, 0.0, 0.0))
    f = tmp_path / "run.mcap"
    with open(f, "wb") as fh:
        w = Writer(fh)
        schema = w.register_msgdef("geometry_msgs/msg/PoseStamped", POSE_STAMPED)
        for ti, (x, y, yaw) in zip(t, measured):
            ns = int(round((100.0 + ti) * 1e9))
            w.write_message("/frog/pose", schema, {
                "header": {"stamp": {"sec": ns // 10**9, "nanosec": ns % 10**9}, "frame_id": "tank"},
                "pose": {"position": {"x": x, "y": y, "z": 0.0},
                         "orientation": {"x": 0.0, "y": 0.0, "z": math.sin(yaw / 2), "w": math.cos(yaw / 2)}}},
                log_time=ns, publish_time=ns)
        w.finish()
    out = tmp_path / "offset.yaml"
    r = subprocess.run(["frog-vision", "tag-offset", str(f), "-o", str(out)], capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0, r.stderr
    params = read_tag_offset(out)
    assert abs(params["offset_yaw"] - offset[2]) < math.radians(0.5) and abs(params["offset_y"] - offset[1]) < 0.001
