"""Tracker latency per 640x480 frame (target: median detection + estimation <= 10 ms
on one core) and tracker_node throughput at 30 fps (no growing backlog).

Frames: a rendered swimming-and-turning sequence (camera_sim defaults, noise 5). Measured on
the same frames in the same run:

- ``Tracker.process`` (ours: search window around the prediction, full-image search when
  it fails; decimate 2, edge refinement on the full image, 1 thread) = detection + pose +
  covariance + filter;
- our detector on the whole image (no window);
- pupil-apriltags with its default settings (quad_decimate 2, 1 thread) on the whole image;
- on the same motion rendered with a tag36h11 tag (OpenCV has no tagStandard41h12): ours,
  pupil-apriltags defaults, and OpenCV's aruco AprilTag detector (DICT_APRILTAG_36h11,
  CORNER_REFINE_APRILTAG), each with its corner error against the renderer's truth.

``--node`` also runs tracker_node as a process and feeds it the frames at 30 fps for 10 s:
odometry count, capture-to-odometry latency (median, max) and whether it grows.

    ./dev run python bench/vision_tracker.py [--frames 300] [--node]
"""
import argparse
import os
import statistics
import time

import cv2
import numpy as np

from frog_vision.core.camera_model import CameraModel
from frog_vision.core.detection import DetectorSettings, TagDetector, to_grey
from frog_vision.core.renderer import RenderSettings, TankRenderer
from frog_vision.core.robot_shape import frog_outline
from frog_vision.core.synthetic import swim_and_turn
from frog_vision.core.tank_calibration import CameraPose
from frog_vision.core.tracker import Tracker


def timed(fn, frames):
    wall, cpu, out = [], [], []
    for i, f in enumerate(frames):
        w, c = time.perf_counter(), time.process_time()
        out.append(fn(i, f))
        wall.append(time.perf_counter() - w)
        cpu.append(time.process_time() - c)
    return statistics.median(wall), statistics.median(cpu), out


def corner_error(found, truth):
    """Median over frames of the largest corner error [px]; corners are matched over the four
    cyclic orders (OpenCV numbers the corners of AprilTag dictionaries from another one)."""
    errs = [min(np.max(np.linalg.norm(np.roll(np.asarray(c), k, axis=0) - t, axis=1)) for k in range(4))
            for c, t in zip(found, truth) if c is not None]
    return (np.median(errs) if errs else np.nan), len(errs)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--node", action="store_true", help="also measure tracker_node at 30 fps")
    a = ap.parse_args()
    cv2.setNumThreads(1)
    cam, pose = CameraModel.realsense_640x480(), CameraPose.overhead(0.8)
    tr = swim_and_turn(a.frames / 30.0)
    shapes = [frog_outline(c) for c in tr.limb_curl]
    seq = {}
    for fam, tid in (("tagStandard41h12", 47), ("tag36h11", 7)):
        r = TankRenderer(cam, pose, RenderSettings(noise_sigma=5.0, tag_family=fam, tag_id=tid))
        frames = [r.render(tr.pose[i], tr.twist[i], shapes[i]) for i in range(len(tr.t))]
        truth = [r.project_tag_corners(tr.pose[i]) for i in range(len(tr.t))]
        seq[fam] = (frames, truth)
    print(f"load average {os.getloadavg()[0]:.2f}; {len(tr.t)} frames 640x480; 1 thread")
    print("| method (family) | median ms/frame wall | median CPU ms | found | corner err px (median of max) | "
          "ours faster by |")
    print("|---|---|---|---|---|---|")
    rows = []
    for fam in seq:
        frames, truth = seq[fam]
        tid = 47 if fam == "tagStandard41h12" else 7
        trk = Tracker(cam, pose, DetectorSettings(family=fam, tag_ids=(tid,)))
        w, c, out = timed(lambda i, f: trk.process(f, float(tr.t[i])), frames)
        err, n = corner_error([o.corners for o in out], truth)
        ours = w
        rows.append((f"Tracker.process, ours ({fam})", w, c, n, err, None))
        det = TagDetector(DetectorSettings(family=fam, tag_ids=(tid,)))
        w, c, out = timed(lambda i, f: det.detect(f), frames)
        err, n = corner_error([o[0].corners if o else None for o in out], truth)
        rows.append((f"our detector, whole image ({fam})", w, c, n, err, w / ours))
        import pupil_apriltags
        pd = pupil_apriltags.Detector(families=fam)          # default settings
        w, c, out = timed(lambda i, f: pd.detect(to_grey(f)), frames)
        mine = [[d for d in o if d.tag_id == tid] for o in out]          # the board's tags are also found
        err, n = corner_error([np.asarray(o[0].corners) - 0.5 if o else None for o in mine], truth)
        rows.append((f"pupil-apriltags defaults ({fam})", w, c, n, err, w / ours))
        if fam == "tag36h11":
            params = cv2.aruco.DetectorParameters()
            params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_APRILTAG
            ad = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11), params)

            def aruco(i, f):
                corners, ids, _ = ad.detectMarkers(to_grey(f))
                if ids is None or tid not in ids.ravel():
                    return None
                return corners[list(ids.ravel()).index(tid)].reshape(4, 2)[::-1]
            w, c, out = timed(aruco, frames)
            err, n = corner_error(out, truth)
            rows.append(("OpenCV aruco AprilTag 36h11 (CORNER_REFINE_APRILTAG)", w, c, n, err, w / ours))
    for name, w, c, n, err, ratio in rows:
        print(f"| {name} | {w * 1e3:.2f} | {c * 1e3:.2f} | {n}/{len(tr.t)} | {err:.3f} | "
              f"{'-' if ratio is None else f'{ratio:.1f}x'} |")
    ours = rows[0][1]
    print(f"target median <= 10 ms: {'met' if ours <= 0.010 else 'NOT met'} ({ours * 1e3:.2f} ms)")
    if a.node:
        node_throughput(seq["tagStandard41h12"][0], cam)


def node_throughput(frames, cam, seconds=10.0, fps=30.0):
    """tracker_node as a process, fed at ``fps``: odometry count and latency over time."""
    import subprocess

    import rclpy
    from nav_msgs.msg import Odometry
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import CameraInfo, Image

    from frog_vision.nodes.messages import array_to_image, camera_info_msg, s_to_stamp, stamp_to_s
    env = dict(os.environ, ROS_DOMAIN_ID=str(150 + os.getpid() % 50), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    os.environ.update(env)
    proc = subprocess.Popen(["tracker_node"], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    rclpy.init()
    node = rclpy.create_node("bench_feeder")
    got = []
    node.create_subscription(Odometry, "/frog/odom",
                             lambda m: got.append((stamp_to_s(m.header.stamp), time.time())), 100)
    qos = QoSProfile(depth=2, reliability=ReliabilityPolicy.RELIABLE)
    pub_i = node.create_publisher(Image, "/camera/image_raw", qos)
    pub_c = node.create_publisher(CameraInfo, "/camera/camera_info", qos)
    end = time.time() + 30
    while pub_i.get_subscription_count() == 0 and time.time() < end:
        rclpy.spin_once(node, timeout_sec=0.1)
    time.sleep(1.0)
    t0 = time.time()
    n = int(seconds * fps)
    for k in range(n):
        t = t0 + k / fps
        while time.time() < t:
            rclpy.spin_once(node, timeout_sec=max(0.0, t - time.time()))
        stamp = s_to_stamp(time.time())
        pub_c.publish(camera_info_msg(cam, stamp, "camera"))
        pub_i.publish(array_to_image(frames[k % len(frames)], stamp, "camera"))
    end = time.time() + 1.0
    while time.time() < end:
        rclpy.spin_once(node, timeout_sec=0.05)
    proc.send_signal(2)
    proc.wait(10)
    lat = np.array([r - s for s, r in got])
    half = len(lat) // 2
    print(f"tracker_node at {fps:g} fps for {seconds:g} s: {len(got)}/{n} odometry messages; capture-to-receive "
          f"latency median {np.median(lat) * 1e3:.1f} ms, max {lat.max() * 1e3:.1f} ms; first half median "
          f"{np.median(lat[:half]) * 1e3:.1f} ms, second half {np.median(lat[half:]) * 1e3:.1f} ms "
          f"(a growing backlog would show as a rising latency)")
    node.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    main()
