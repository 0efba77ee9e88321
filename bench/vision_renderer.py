"""Camera-simulator frame rate at 640x480 (target: >= 60 frames/s on one core).

Frames of a swimming-and-turning sequence with the defaults of ``camera_sim`` (5-sample motion
blur over 10 ms, 2x supersampling of the robot, noise, uneven lighting), and with lens
distortion. Baseline measured in the same run: the straightforward way to draw the same frame,
the whole image at the supersampled resolution (background, robot, tag) and shrunk with area
averaging once per blur sample, as a renderer without a region of interest does.

    ./dev run python bench/vision_renderer.py [--frames 300]
"""
import argparse
import os
import statistics
import time

import cv2
import numpy as np

from frog_vision.core.camera_model import CameraModel
from frog_vision.core.renderer import RenderSettings, TankRenderer
from frog_vision.core.robot_shape import frog_outline
from frog_vision.core.synthetic import swim_and_turn
from frog_vision.core.tank_calibration import CameraPose


def timed(fn, n):
    wall, cpu = [], []
    for i in range(n):
        w, c = time.perf_counter(), time.process_time()
        fn(i)
        wall.append(time.perf_counter() - w)
        cpu.append(time.process_time() - c)
    return statistics.median(wall), statistics.median(cpu)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=300)
    a = ap.parse_args()
    cv2.setNumThreads(1)                              # one core
    tr = swim_and_turn(a.frames / 30.0)
    shapes = [frog_outline(c) for c in tr.limb_curl]
    pose = CameraPose.overhead(0.8)
    cams = {"pinhole": CameraModel.realsense_640x480(),
            "distorted": CameraModel(640, 480, CameraModel.realsense_640x480().K, [-0.12, 0.05, 0.001, -0.001, 0.0])}
    n = len(tr.t)
    print(f"load average {os.getloadavg()[0]:.2f}; {n} frames 640x480; OpenCV threads {cv2.getNumThreads()}")
    print("| renderer | median ms/frame (wall) | median CPU ms | frames/s (wall) | vs baseline |")
    print("|---|---|---|---|---|")
    # baseline: full-frame supersampled drawing
    base_r = TankRenderer(cams["pinhole"], pose, RenderSettings())
    big_bg = cv2.resize(base_r._background_lit, (1280, 960), interpolation=cv2.INTER_LINEAR)
    tex = cv2.cvtColor(base_r._tag_texture, cv2.COLOR_GRAY2BGR)
    to_big = np.array([[2, 0, 0.5], [0, 2, 0.5], [0, 0, 1.0]])

    def baseline(i):
        from frog_common.se2 import twist_arc
        acc = np.zeros((960, 1280, 3), np.float32)
        for tau in np.linspace(-0.005, 0.005, 5):
            p = twist_arc(tr.pose[i], tr.twist[i], tau)
            layer = big_bg.copy()
            c, s = np.cos(p[2]), np.sin(p[2])
            H = to_big @ base_r._Htag @ np.array([[c, -s, p[0]], [s, c, p[1]], [0, 0, 1.0]]) @ base_r._tag_affine
            cv2.warpPerspective(tex, H, (1280, 960), dst=layer, borderMode=cv2.BORDER_TRANSPARENT)
            acc += layer
        small = cv2.resize(acc / 5, (640, 480), interpolation=cv2.INTER_AREA).astype(np.uint8)
        return cv2.add(small, np.zeros_like(small))

    bw, bc = timed(baseline, min(n, 60))
    rows = [("full-frame supersampled (baseline)", bw, bc)]
    for name, cam in cams.items():
        r = TankRenderer(cam, pose, RenderSettings())
        w, c = timed(lambda i: r.render(tr.pose[i], tr.twist[i], shapes[i]), n)
        rows.append((f"TankRenderer, {name}", w, c))
    r = TankRenderer(cams["pinhole"], pose, RenderSettings(exposure=0.0, noise_sigma=0.0))
    w, c = timed(lambda i: r.render(tr.pose[i], tr.twist[i], shapes[i]), n)
    rows.append(("TankRenderer, no blur, no noise", w, c))
    for name, w, c in rows:
        print(f"| {name} | {w * 1e3:.2f} | {c * 1e3:.2f} | {1 / w:.0f} | {bw / w:.1f}x |")
    print(f"target >= 60 frames/s: {'met' if 1 / rows[1][1] >= 60 else 'NOT met'} "
          f"({1 / rows[1][1]:.0f} frames/s with the camera_sim defaults)")


if __name__ == "__main__":
    main()
