"""``frog-vision``: tank calibration, offline tracking and rendering from the command line."""
from __future__ import annotations

import argparse
import csv
import math
import sys
from pathlib import Path

import numpy as np
from frog_common.se2 import yaw_of

EXAMPLES = """examples:
  # camera pose over the tank from photos of the board (tag36h11, default layout)
  frog-vision calibrate-tank board_*.png --camera-info cam.yaml -o tank.yaml
  # a video (or a folder of images) -> poses and velocities as CSV, plus an annotated video
  frog-vision track run.mp4 --camera-info cam.yaml --tank-calibration tank.yaml -o run.csv --video run_annotated.mp4
  # a simulated trajectory (or the built-in swim) -> video + exact ground truth
  frog-vision render --demo swim --duration 10 -o runs/render_swim
  frog-vision render --trajectory traj.csv -o runs/render_traj --noise 5 --jitter 0.2
  frog-log export rec.mcap -o csv/ && frog-vision render --trajectory csv/frog__sim__odom.csv -o runs/render_rec
  # and back: track the rendered video with the files render wrote
  frog-vision track runs/render_swim/frames.mp4 --camera-info runs/render_swim/camera_info.yaml \\
      --tank-calibration runs/render_swim/tank_calibration.yaml -o runs/render_swim/track.csv
"""

IMAGE_SUFFIXES = {".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff"}


class UsageError(Exception):
    """Bad input: the message names it; exit code 2."""


def _camera(path):
    from frog_vision.core.camera_model import CameraModel
    if path is None:
        return CameraModel.realsense_640x480()
    try:
        return CameraModel.from_yaml(path)
    except (OSError, ValueError) as exc:
        raise UsageError(f"--camera-info: {exc}") from exc


def _frames(source: Path, fps: float):
    """(stamp, BGR image, name) from a video file or an image folder."""
    import cv2
    if source.is_dir():
        files = sorted(p for p in source.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
        if not files:
            raise UsageError(f"{source}: no images ({', '.join(sorted(IMAGE_SUFFIXES))})")
        for i, f in enumerate(files):
            img = cv2.imread(str(f), cv2.IMREAD_COLOR)
            if img is None:
                raise UsageError(f"{f}: not a readable image")
            yield i / fps, img, f.name
        return
    if not source.is_file():
        raise UsageError(f"{source}: no such file or folder")
    if source.suffix.lower() in IMAGE_SUFFIXES:
        img = cv2.imread(str(source), cv2.IMREAD_COLOR)
        if img is None:
            raise UsageError(f"{source}: not a readable image")
        yield 0.0, img, source.name
        return
    cap = cv2.VideoCapture(str(source))
    if not cap.isOpened():
        raise UsageError(f"{source}: not a readable video")
    rate = cap.get(cv2.CAP_PROP_FPS) or fps
    i = 0
    while True:
        ok, img = cap.read()
        if not ok:
            break
        yield i / rate, img, f"{source.name}#{i}"
        i += 1
    cap.release()
    if i == 0:
        raise UsageError(f"{source}: the video has no readable frames")


def cmd_calibrate_tank(a) -> int:
    import cv2

    from frog_vision.core.detection import DetectorSettings, TagDetector
    from frog_vision.core.tank_calibration import Board, calibrate_tank
    cam = _camera(a.camera_info)
    try:
        board = Board.from_yaml(a.board)
    except (OSError, ValueError) as exc:
        raise UsageError(f"--board: {exc}") from exc
    det = TagDetector(DetectorSettings(family=board.family, tag_ids=()))
    all_dets, last = [], None
    for src in a.images:
        for _, img, name in _frames(Path(src), 30.0):
            if (img.shape[1], img.shape[0]) != (cam.width, cam.height):
                _size_error(img, cam, name)
            d = det.detect(img)
            print(f"{name}: board tags {sorted(x.tag_id for x in d if board.tag(x.tag_id))}")
            all_dets.append(d)
            last = (img, d)
    try:
        cal = calibrate_tank(cam, all_dets, board, str(a.board or "default"))
    except ValueError as exc:
        raise UsageError(str(exc)) from exc
    cal.to_yaml(a.output)
    p = cal.pose
    print(f"camera at x {p.position[0]:+.4f} y {p.position[1]:+.4f} z {p.position[2]:.4f} m, tilt "
          f"{np.degrees(p.tilt):.2f} deg; reprojection RMS {cal.reprojection_rms_px:.3f} px "
          f"(max {cal.reprojection_max_px:.3f}) over {cal.n_points} corners -> {a.output}")
    if a.plot and last is not None:
        img = last[0].copy()
        for t in board.tags:
            uv = p.project(cam, t.corners())
            cv2.polylines(img, [np.round(uv * 4).astype(np.int32)], True, (0, 0, 255), 1, cv2.LINE_AA, 2)
        cv2.imwrite(str(a.plot), img)
        print(f"reprojected board -> {a.plot}")
    return 0


def _size_error(img, cam, name):
    raise UsageError(f"{name}: image is {img.shape[1]}x{img.shape[0]} but the camera model is "
                     f"{cam.width}x{cam.height}")


def cmd_track(a) -> int:
    import cv2
    from tqdm import tqdm

    from frog_vision.core.detection import DetectorSettings
    from frog_vision.core.pose import PoseSettings
    from frog_vision.core.tank_calibration import CameraPose, TankCalibration
    from frog_vision.core.tracker import Tracker
    cam = _camera(a.camera_info)
    if a.tank_calibration:
        try:
            pose = TankCalibration.from_yaml(a.tank_calibration).pose
        except (OSError, ValueError) as exc:
            raise UsageError(f"--tank-calibration: {exc}") from exc
    else:
        pose = CameraPose.overhead(0.8)
        print("no --tank-calibration: assuming the default camera pose 0.8 m over the tank", file=sys.stderr)
    tracker = Tracker(cam, pose, DetectorSettings(family=a.family, tag_ids=(a.tag_id,)),
                      PoseSettings(tag_size=a.tag_size, tag_height=a.tag_height))
    writer = None
    rows = []
    for t, img, name in tqdm(_frames(Path(a.source), a.fps), desc="tracking", unit="frame"):
        if (img.shape[1], img.shape[0]) != (cam.width, cam.height):
            _size_error(img, cam, name)
        r = tracker.process(img, t)
        m, s = r.measurement, r.state
        rows.append([f"{t:.6f}", int(m is not None)]
                    + ([f"{v:.6f}" for v in m.pose] if m else ["", "", ""])
                    + ([f"{v:.6f}" for v in np.concatenate([s.pose, s.body_velocity])] if s else [""] * 6)
                    + [f"{r.compute_s * 1e3:.3f}", r.reason or ""])
        if a.video:
            if writer is None:
                writer = cv2.VideoWriter(str(a.video), cv2.VideoWriter_fourcc(*"mp4v"), a.fps,
                                         (img.shape[1], img.shape[0]))
            out = img.copy()
            if r.corners is not None:
                cv2.polylines(out, [np.round(r.corners * 4).astype(np.int32)], True, (0, 0, 255), 1, cv2.LINE_AA, 2)
            if s is not None:
                cv2.putText(out, f"v {s.body_velocity[0] * 100:+.1f} cm/s  w {np.degrees(s.body_velocity[2]):+.0f} "
                            "deg/s", (8, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 255), 1, cv2.LINE_AA)
            writer.write(out)
    if writer is not None:
        writer.release()
    with open(a.output, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["t", "detected", "x_measured", "y_measured", "heading_measured", "x", "y", "heading",
                    "forward", "lateral", "yaw_rate", "compute_ms", "reason"])
        w.writerows(rows)
    n = len(rows)
    det = sum(r[1] for r in rows)
    print(f"{n} frames, tag accepted in {det} ({det / max(n, 1):.1%}) -> {a.output}"
          + (f", {a.video}" if a.video else ""))
    if a.plot:
        _plot_track(rows, a.plot)
    return 0


def _plot_track(rows, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    d = np.array([[float(v) if v != "" else np.nan for v in r[:11]] for r in rows])
    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    ax[0].plot(d[:, 3], d[:, 2], ".", ms=2, label="measured")
    ax[0].plot(d[:, 6], d[:, 5], "-", label="filtered")
    ax[0].set(xlabel="y [m]", ylabel="x [m]", aspect="equal", title="path")
    ax[0].legend()
    ax[1].plot(d[:, 0], d[:, 8] * 100, label="forward [cm/s]")
    ax[1].plot(d[:, 0], np.degrees(d[:, 10]) / 10, label="yaw rate [10 deg/s]")
    ax[1].set(xlabel="t [s]", title="filtered velocities")
    ax[1].legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    print(f"plot -> {path}")


def _read_trajectory(path: Path, fps: float):
    from frog_vision.core.synthetic import Trajectory
    if not path.is_file():
        raise UsageError(f"--trajectory {path}: no such file")
    try:
        with open(path) as f:
            reader = csv.DictReader(f)
            rows = list(reader)
            cols = reader.fieldnames or []
        if "pose.pose.position.x" in cols:          # frog-log export of a nav_msgs/Odometry topic
            rows, cols = [_odometry_row(r) for r in rows], ["t", "x", "y", "heading", "forward", "lateral", "yaw_rate"]
        for c in ("t", "x", "y", "heading"):
            if c not in cols:
                raise UsageError(f"--trajectory {path}: column {c!r} is missing (need t, x, y, heading; optional "
                                 "forward, lateral, yaw_rate)")
        d = {c: np.array([float(r[c]) for r in rows]) for c in cols if c in
             ("t", "x", "y", "heading", "forward", "lateral", "yaw_rate")}
    except ValueError as exc:
        raise UsageError(f"--trajectory {path}: {exc}") from exc
    if len(d["t"]) < 2 or np.any(np.diff(d["t"]) <= 0):
        raise UsageError(f"--trajectory {path}: needs >= 2 rows with increasing t")
    t = np.arange(d["t"][0], d["t"][-1], 1.0 / fps)
    heading = np.unwrap(d["heading"])
    pose = np.column_stack([np.interp(t, d["t"], d["x"]), np.interp(t, d["t"], d["y"]),
                            np.interp(t, d["t"], heading)])
    if all(c in d for c in ("forward", "lateral", "yaw_rate")):
        twist = np.column_stack([np.interp(t, d["t"], d[c]) for c in ("forward", "lateral", "yaw_rate")])
    else:
        g = np.gradient(pose, t, axis=0)
        c, s = np.cos(pose[:, 2]), np.sin(pose[:, 2])
        twist = np.column_stack([c * g[:, 0] + s * g[:, 1], -s * g[:, 0] + c * g[:, 1], g[:, 2]])
    return Trajectory(t, pose, twist, np.zeros(len(t)))


def _odometry_row(r: dict) -> dict:
    """t, x, y, heading and the body twist from a flattened nav_msgs/Odometry row."""
    qz, qw = float(r["pose.pose.orientation.z"]), float(r["pose.pose.orientation.w"])
    return {"t": int(r["header.stamp.sec"]) + int(r["header.stamp.nanosec"]) * 1e-9,
            "x": r["pose.pose.position.x"], "y": r["pose.pose.position.y"], "heading": 2 * np.arctan2(qz, qw),
            "forward": r["twist.twist.linear.x"], "lateral": r["twist.twist.linear.y"],
            "yaw_rate": r["twist.twist.angular.z"]}


def cmd_render(a) -> int:
    import cv2
    from tqdm import tqdm

    from frog_vision.core.renderer import RenderSettings, TankRenderer
    from frog_vision.core.robot_shape import frog_outline
    from frog_vision.core.synthetic import swim_and_turn
    from frog_vision.core.tank_calibration import CameraPose, TankCalibration
    cam = _camera(a.camera_info)
    traj = _read_trajectory(Path(a.trajectory), a.fps) if a.trajectory else swim_and_turn(a.duration, a.fps,
                                                                                       seed=a.seed)
    out = Path(a.output)
    out.mkdir(parents=True, exist_ok=True)
    pose = CameraPose.overhead(a.camera_height)
    try:
        r = TankRenderer(cam, pose, RenderSettings(noise_sigma=a.noise, exposure=a.exposure, brightness=a.brightness,
                                                   corner_jitter_px=a.jitter, seed=a.seed))
    except ValueError as exc:
        raise UsageError(str(exc)) from exc
    writer = cv2.VideoWriter(str(out / "frames.mp4"), cv2.VideoWriter_fourcc(*"mp4v"), a.fps, (cam.width, cam.height))
    with open(out / "ground_truth.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["t", "x", "y", "heading", "forward", "lateral", "yaw_rate"])
        for i in tqdm(range(len(traj.t)), desc="rendering", unit="frame"):
            img = r.render(traj.pose[i], traj.twist[i], frog_outline(float(traj.limb_curl[i])))
            writer.write(img)
            if a.png:
                cv2.imwrite(str(out / f"frame_{i:05d}.png"), img)
            w.writerow([f"{traj.t[i]:.6f}"] + [f"{v:.7f}" for v in np.concatenate([traj.pose[i], traj.twist[i]])])
    writer.release()
    cam.to_yaml(out / "camera_info.yaml")
    TankCalibration(pose, 0.0, 0.0, 0, (), (cam.width, cam.height), "ground truth of the render").to_yaml(
        out / "tank_calibration.yaml")
    print(f"{len(traj.t)} frames -> {out / 'frames.mp4'}; ground truth {out / 'ground_truth.csv'}; "
          f"camera_info.yaml and tank_calibration.yaml (exact) beside them")
    return 0


def _read_swim(path: Path):
    """(t, measured body poses) of a tracker CSV (frog-vision track) or an MCAP's /frog/pose."""
    if not path.is_file():
        raise UsageError(f"{path}: no such file")
    if path.suffix == ".mcap":
        from mcap.reader import make_reader
        from mcap_ros2.decoder import DecoderFactory
        rows = []
        with open(path, "rb") as fh:
            messages = [m for _, _, _, m in make_reader(fh, decoder_factories=[DecoderFactory()])
                        .iter_decoded_messages(topics=["/frog/pose"])]
        for m in messages:
            q = m.pose.orientation
            rows.append([m.header.stamp.sec + m.header.stamp.nanosec * 1e-9, m.pose.position.x, m.pose.position.y,
                         yaw_of(q)])
        if not rows:
            raise UsageError(f"{path}: no /frog/pose messages (record the tracker's pose)")
        a = np.array(sorted(rows))
        return a[:, 0], a[:, 1:]
    with open(path) as f:
        reader = csv.DictReader(f)
        cols = reader.fieldnames or []
        need = ("t", "x_measured", "y_measured", "heading_measured")
        if any(c not in cols for c in need):
            raise UsageError(f"{path}: needs columns {', '.join(need)} (the CSV of frog-vision track)")
        rows = [[float(r[c]) for c in need] for r in reader if r.get("x_measured")]
    if not rows:
        raise UsageError(f"{path}: no row with a detected tag")
    a = np.array(rows)
    return a[:, 0], a[:, 1:]


def cmd_tag_offset(a) -> int:
    from frog_vision.core.pose import PoseSettings
    from frog_vision.core.tag_offset import compose, estimate_tag_offset, invert, write_tag_offset
    t, measured = _read_swim(Path(a.log))
    used = tuple(a.measured_offset) if a.measured_offset else (PoseSettings().offset_x, 0.0, 0.0)
    tag = compose(measured, invert(used))     # back to the tag's own pose
    try:
        r = estimate_tag_offset(t, tag, window=a.window)
    except ValueError as exc:
        raise UsageError(f"{a.log}: {exc}") from exc
    write_tag_offset(r, a.output, source=str(a.log))
    print(f"offset_yaw {math.degrees(r.offset_yaw):+.2f} +- {math.degrees(r.offset_yaw_sd):.2f} deg, offset_x "
          f"{r.offset_x * 1e3:+.2f} +- {r.offset_x_sd * 1e3:.2f} mm, offset_y (lateral) {r.offset_y * 1e3:+.2f} +- "
          f"{r.offset_y_sd * 1e3:.2f} mm from {r.windows} windows -> {a.output} (frog-twin --tag-offset)")
    return 0


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="frog-vision", description=__doc__, epilog=EXAMPLES,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="command", required=True)
    c = sub.add_parser("calibrate-tank", help="camera pose over the tank from board images -> YAML",
                       epilog=EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)
    c.add_argument("images", nargs="+", help="images (or folders / videos) of the board seen by the fixed camera")
    c.add_argument("--camera-info", help="camera_calibration YAML (default: RealSense 640x480)")
    c.add_argument("--board", help="board YAML (default: the package's six-tag layout)")
    c.add_argument("-o", "--output", default="tank_calibration.yaml")
    c.add_argument("--plot", help="PNG with the board reprojected through the result")
    c.set_defaults(func=cmd_calibrate_tank)
    t = sub.add_parser("track", help="video or image folder -> CSV of poses and velocities",
                       epilog=EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)
    t.add_argument("source", help="video file, image file or folder of images")
    t.add_argument("--camera-info")
    t.add_argument("--tank-calibration")
    t.add_argument("--family", default="tagStandard41h12")
    t.add_argument("--tag-id", type=int, default=47)
    t.add_argument("--tag-size", type=float, default=0.047, help="[m]")
    t.add_argument("--tag-height", type=float, default=0.0, help="[m] above the board plane")
    t.add_argument("--fps", type=float, default=30.0, help="frame rate of an image folder [Hz]")
    t.add_argument("-o", "--output", default="track.csv")
    t.add_argument("--video", help="annotated video (mp4)")
    t.add_argument("--plot", help="PNG of the path and velocities")
    t.set_defaults(func=cmd_track)
    r = sub.add_parser("render", help="simulated trajectory -> video + ground-truth CSV",
                       epilog=EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)
    g = r.add_mutually_exclusive_group()
    g.add_argument("--trajectory", help="CSV with t, x, y, heading [, forward, lateral, yaw_rate] (SI), or "
                   "'frog-log export' of a recorded frog/sim/odom (nav_msgs/Odometry)")
    g.add_argument("--demo", choices=("swim",), default="swim", help="built-in swimming-and-turning trajectory")
    r.add_argument("--duration", type=float, default=10.0, help="[s] of the demo")
    r.add_argument("--fps", type=float, default=30.0)
    r.add_argument("--camera-info")
    r.add_argument("--camera-height", type=float, default=0.8, help="[m] over the tank")
    r.add_argument("--noise", type=float, default=2.0, help="sensor noise [grey levels]")
    r.add_argument("--exposure", type=float, default=0.01, help="[s] (motion blur)")
    r.add_argument("--brightness", type=float, default=1.0)
    r.add_argument("--jitter", type=float, default=0.0, help="tag corner jitter [px]")
    r.add_argument("--seed", type=int, default=0)
    r.add_argument("--png", action="store_true", help="also write every frame as PNG")
    r.add_argument("-o", "--output", default="runs/render")
    r.set_defaults(func=cmd_render)
    o = sub.add_parser("tag-offset", help="straight B swim (track CSV or MCAP) -> tag-to-body offset YAML",
                       description="Measure the tracker's tag-to-body offset (offset_yaw, offset_x, offset_y with "
                                   "their bootstrap spread) from a recorded straight swim; the file is what "
                                   "frog-twin --tag-offset and tracker_node's offset_* parameters take.")
    o.add_argument("log", help="frog-vision track CSV, or an MCAP recording with /frog/pose")
    o.add_argument("--measured-offset", type=float, nargs=3, metavar=("X", "Y", "YAW"),
                   help="offset the log's poses were measured with [m, m, rad] (default: the tracker's default)")
    o.add_argument("--window", type=float, default=1.5, help="analysis window [s] (about one period)")
    o.add_argument("-o", "--output", default="tag_offset.yaml")
    o.set_defaults(func=cmd_tag_offset)
    return ap


def main(argv=None) -> int:
    a = build_parser().parse_args(argv)
    try:
        return a.func(a)
    except UsageError as exc:
        print(f"frog-vision {a.command}: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
