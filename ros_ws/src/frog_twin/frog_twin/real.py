"""Real mode of ``frog-twin``: the same graph with the real camera and the relay's serial port.

``frog-twin --robot-port /dev/ttyACM0 --camera /dev/video0 --camera-info cam.yaml
--tank-calibration tank.yaml --tag-offset tag_offset.yaml --path sine`` starts the graph
file's ``real`` mode (camera_node, tracker_node, image_preview, bridge_node, planner_node,
recorder; every node on the system clock), runs the pre-flight checks and starts the
planner only when all pass; nothing is actuated before (the planner waits for ``~/start``
and publishes primitive I meanwhile).

One stop for everything: ``frog/stop`` (std_msgs/Empty). A topic rather than a service
because the stop has several receivers that must all act at once (the planner stops
deciding, the bridge cancels its scheduled pulses and refuses new ones until
``~/clear_emergency``) and a sender must not wait for any of them to answer; any tool can
send it (``ros2 topic pub --once /frog/stop std_msgs/msg/Empty``). ``frog-twin`` itself
sends it on Ctrl-C, when a liveness contract of the graph file says so (the tag not seen for
``tag_lost_after_s``, a latched emergency; a tracker that hears nothing while the camera
publishes is restarted instead), when a node of the loop is out of restarts (a crashed node is
restarted with back-off, as in the twin), at the goal and at ``--duration``; then it writes the
same report as the twin (trajectory PNG, MP4 with the overlay, JSON, MCAP), measured on the
tracked pose since there is no ground truth.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from soft_robot_common.graph import load_graph
from soft_robot_common.tool_signals import redirect_stop_signals

from frog_twin.core import twin_report
from frog_twin.core.metrics import best_window_rate
from frog_twin.core.twin_recording import read_twin_recording
from frog_common.se2 import yaw_of

#: What the pre-flight waits for at most per check [s].
PREFLIGHT_TIMEOUT_S = 20.0
#: Camera rate window and the fraction of the nominal rate it must reach.
RATE_WINDOW_S = 2.0
RATE_FRACTION = 0.8
#: Q lines (frog/imu messages) the relay must deliver in the pre-flight.
MIN_Q_LINES = 3


class PreflightError(RuntimeError):
    """One or more pre-flight checks failed; ``failures`` holds each message."""

    def __init__(self, failures):
        super().__init__("pre-flight failed, nothing was actuated:\n" + "\n".join(f"  - {f}" for f in failures))
        self.failures = list(failures)


@dataclass
class Check:
    name: str
    ok: bool
    message: str

    def __post_init__(self):
        self.ok = bool(self.ok)


def real_graph(args, name: str, out: Path, path_settings, settings):
    """The real robot's processes: the graph file's real mode with this run's devices and files."""

    from frog_twin.twin import GRAPH_FILE, transitions_choice
    camera_info = str(args.camera_info) if getattr(args, "camera_info", None) else None
    tracker = {"camera_info_file": camera_info,
               "tank_calibration_file": str(args.tank_calibration) if args.tank_calibration else None}
    tracker.update(getattr(args, "tag_offset_params", None) or {})
    overrides = {
        "recorder": {"output_dir": str(out / "recording"), "file_prefix": name},
        "camera_node": {"source": str(args.camera or "/dev/video0"), "camera_info_file": camera_info,
                        "fps": float(args.camera_fps)},
        "tracker_node": tracker,
        "image_preview": {"rate_hz": args.video_rate},
        "bridge_node": {"port": str(args.robot_port or "/dev/ttyACM0")},
        "planner_node": {"library_file": str(args.library), **settings.as_dict(), **path_settings.as_dict(),
                         **transitions_choice(args)[0]},
    }
    return load_graph(getattr(args, "graph_file", None) or GRAPH_FILE, "real", overrides,
                      exclude=transitions_choice(args)[1])


def reference_sim_node(args, pose):
    """sim_node beside the real robot, never in the loop: it starts at the tracked pose, on the
    system clock, and executes the planner's primitives; its frog/sim/odom is the prediction the
    report sets beside the tracked trajectory (nothing in the loop reads it)."""
    from frog_twin.twin import GRAPH_FILE
    x, y, heading = (float(v) for v in pose)
    return load_graph(GRAPH_FILE, "sim", {"sim_node": {
        "publish_clock": False, "real_time_factor": 1.0, "execute_primitives": True, "initial_x": x,
        "initial_y": y, "initial_heading": heading, "limb_strength_sd": 0.0, "kick_strength_sd": 0.0,
        "odom_alias_topic": ""}})["sim_node"]


class RealWatch:
    """The pre-flight's and the run's view of the graph (an rclpy node on the run's domain)."""

    def __init__(self, domain):
        from diagnostic_msgs.msg import DiagnosticArray
        from geometry_msgs.msg import PoseStamped
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        from sensor_msgs.msg import CameraInfo, Imu
        from std_msgs.msg import Empty

        from frog_twin.twin import PlannerWatch
        self.base = PlannerWatch(domain)
        node = self.base.node
        self.frames = []          # (monotonic arrival, width, height)
        self.poses = []           # (monotonic arrival, x, y, yaw)
        self.imu = 0
        self.link_state = None
        self.link_message = None
        self.stops = 0
        self.interrupted = []     # Ctrl-C, SIGTERM, SIGHUP (the stop-signal handler of run_real)
        # camera_node publishes one camera_info per frame (with its size): the rate without the pixels
        node.create_subscription(CameraInfo, "/camera/camera_info", self._on_frame, 50)
        node.create_subscription(PoseStamped, "/frog/pose", self._on_pose, 10)
        node.create_subscription(Imu, "/frog/imu", self._on_imu, 10)
        node.create_subscription(DiagnosticArray, "/diagnostics", self._on_diag, 10)
        node.create_subscription(Empty, "/frog/stop", self._on_stop, 10)
        self.stop_pub = node.create_publisher(Empty, "/frog/stop", QoSProfile(
            depth=10, reliability=ReliabilityPolicy.RELIABLE))
        self.Empty = Empty

    def _on_frame(self, msg) -> None:
        self.frames.append((time.monotonic(), msg.width, msg.height))

    def _on_pose(self, msg) -> None:
        q = msg.pose.orientation
        yaw = yaw_of(q)
        self.poses.append((time.monotonic(), msg.pose.position.x, msg.pose.position.y, yaw))

    def _on_imu(self, msg) -> None:
        self.imu += 1

    def _on_diag(self, msg) -> None:
        for s in msg.status:
            if s.name.startswith("bridge_node:"):
                values = {kv.key: kv.value for kv in s.values}
                self.link_state = values.get("state")
                self.link_message = s.message

    def _on_stop(self, msg) -> None:
        self.stops += 1

    def spin(self, seconds: float) -> None:
        self.base.spin(seconds)

    def stop_all(self) -> None:
        for _ in range(3):       # reliable; repeated so a late-joining subscriber also hears it
            self.stop_pub.publish(self.Empty())
            self.base.spin(0.02)

    def close(self) -> None:
        self.base.close()


def _image_size_problem(what: str, path, size, frame_size) -> str | None:
    if size and tuple(int(v) for v in size) != tuple(frame_size):
        return (f"{what} {path} is for {size[0]}x{size[1]} images but the camera delivers "
                f"{frame_size[0]}x{frame_size[1]} frames; calibrate again in this camera mode or set the camera's "
                f"size to match")
    return None


def preflight(args, watch: RealWatch, procs, path, timeout: float = PREFLIGHT_TIMEOUT_S) -> list[Check]:
    """Run every pre-flight check (they wait in parallel, each up to ``timeout``); returns them all."""
    from frog_vision.core.camera_model import CameraModel
    from frog_vision.core.tank_calibration import CameraPose, TankCalibration
    t0 = time.monotonic()
    fps = float(args.camera_fps)

    def died():
        return [p for p in procs if not p.running()]

    def wait(pred, limit=timeout):
        end = t0 + limit
        while not pred() and time.monotonic() < end and not died() and not watch.interrupted:
            watch.spin(0.05)
        return pred()

    checks = []
    # 1. the camera's rate: the best whole window within the pre-flight (the first seconds, while
    # every node loads, may be slow on a busy machine; a camera too slow for the rate is so in all)
    def rate():
        return best_window_rate([t for t, _, _ in watch.frames], RATE_WINDOW_S)

    got_frames = wait(lambda: len(watch.frames) >= 1)
    if not got_frames:
        checks.append(Check("camera", False, f"camera {args.camera}: no frame (camera/camera_info) within "
                                             f"{timeout:.0f} s (see camera_node.log)"))
    else:
        wait(lambda: (rate() or 0.0) >= RATE_FRACTION * fps)
        best = rate() or 0.0
        ok = best >= RATE_FRACTION * fps
        checks.append(Check("camera", ok, f"camera {args.camera}: {best:.1f} frames/s in the best "
                                          f"{RATE_WINDOW_S:g} s ({'at least' if ok else 'below'} "
                                          f"{RATE_FRACTION:.0%} of its {fps:g} Hz)"))
    # 2. image sizes of the calibration files
    frame_size = (watch.frames[-1][1], watch.frames[-1][2]) if watch.frames else None
    camera = None
    if args.camera_info:
        try:
            camera = CameraModel.from_yaml(args.camera_info)
        except (OSError, ValueError) as exc:
            checks.append(Check("calibration", False, f"camera info {args.camera_info}: {exc}"))
            camera = None
    tank = None
    if args.tank_calibration:
        try:
            tank = TankCalibration.from_yaml(args.tank_calibration)
        except (OSError, ValueError) as exc:
            checks.append(Check("calibration", False, f"tank calibration: {exc}"))
    if frame_size is not None:
        problems = [p for p in (
            _image_size_problem("camera info", args.camera_info, (camera.width, camera.height) if camera else None,
                                frame_size),
            _image_size_problem("tank calibration", args.tank_calibration, tank.image_size if tank else None,
                                frame_size)) if p]
        checks.append(Check("calibration", not problems, "; ".join(problems) or
                            f"calibration image size matches the camera's {frame_size[0]}x{frame_size[1]}"))
    # 3. the tag, inside the tank (inside the camera's view of the tank plane, with a margin)
    have_pose = wait(lambda: len(watch.poses) >= 3)
    pose = watch.poses[-1][1:] if watch.poses else None
    if not have_pose:
        checks.append(Check("tag", False, f"tag not detected: {len(watch.poses)} pose(s) on /frog/pose within "
                                          f"{timeout:.0f} s (is the robot in view, the tag id/family right, "
                                          "the light enough?)"))
    else:
        inside = True
        where = ""
        if frame_size is not None:
            cam = (camera or CameraModel.realsense_640x480()).scaled(*frame_size)
            cam_pose = tank.pose if tank else CameraPose.overhead(0.8)
            u, v = cam_pose.project(cam, [[pose[0], pose[1], 0.0]])[0]
            margin = 0.05 * min(frame_size)
            inside = margin <= u <= frame_size[0] - margin and margin <= v <= frame_size[1] - margin
            where = f" (pixel {u:.0f}, {v:.0f} of {frame_size[0]}x{frame_size[1]})"
        checks.append(Check("tag", inside, f"tag at x {pose[0]:.3f} m, y {pose[1]:.3f} m, heading "
                                           f"{math.degrees(pose[2]):.0f} deg{where}"
                            + ("" if inside else ": outside the tank's view (margin 5 %)")))
    # 4. the link: ready, and Q lines from the relay
    link_ok = wait(lambda: watch.link_state == "ready" and watch.imu >= MIN_Q_LINES)
    if link_ok:
        checks.append(Check("link", True, f"link to {args.robot_port} ready, {watch.imu} Q lines"))
    elif watch.link_state != "ready":
        checks.append(Check("link", False, f"link to {args.robot_port} is {watch.link_state or 'not reported'}"
                                           f" ({watch.link_message or 'no diagnostics from bridge_node'}) after "
                                           f"{timeout:.0f} s"))
    else:
        checks.append(Check("link", False, f"link to {args.robot_port}: {watch.imu} 'Central: Q' line(s) in "
                                           f"{timeout:.0f} s, need {MIN_Q_LINES} (relay or robot silent: is the "
                                           f"robot on and paired?) - {watch.link_message}"))
    # 5. the library, as the planner loaded it
    base = watch.base
    wait(lambda: base.last is not None)
    if base.last is None:
        checks.append(Check("library", False, "no status from planner_node (see planner_node.log)"))
    elif base.state == base.Status.STATE_ERROR:
        checks.append(Check("library", False, f"planner_node: {base.last.message}"))
    else:
        checks.append(Check("library", True, f"library {args.library} loaded by planner_node"))
    # 6. the path starts within reach of the robot's pose
    if pose is not None:
        x0, y0 = (float(v) for v in path.points[0])
        d = math.hypot(pose[0] - x0, pose[1] - y0)
        ok = d <= args.start_tolerance
        checks.append(Check("start", ok, f"path starts {d * 100:.1f} cm from the robot "
                                         f"({'within' if ok else 'beyond'} --start-tolerance "
                                         f"{args.start_tolerance * 100:.1f} cm)"
                            + ("" if ok else f"; place the robot at x {x0:.3f}, y {y0:.3f} m or move the path")))
    dead = died()
    if dead:
        checks.append(Check("nodes", False, "; ".join(f"{p.name} exited (code {p.proc.returncode}), log "
                                                      f"{p.log_path}" for p in dead)))
    return checks


def run_real(args, name: str, out: Path, path_settings, settings) -> dict:
    """One run on the real robot: pre-flight, follow, stop, report. Raises PreflightError.

    While following, a node that exits is restarted with back-off (as in the twin; a planner
    resumes at its progress); out of restarts, or when a liveness contract of the graph file says
    so (the tag lost, an emergency), the run stops with the reason.
    """
    from frog_twin.core.twin_recording import recordings
    from frog_twin.fault_injection import RunObserver
    from frog_twin.supervised_run import SupervisedGraph, graph_liveness, run_domain
    from frog_twin.twin import GRAPH_FILE, _restarter
    out.mkdir(parents=True, exist_ok=True)
    earlier = recordings(out / "recording")
    graph = real_graph(args, name, out, path_settings, settings)
    path = path_settings.build()
    domain = run_domain(args.domain)
    watch = RealWatch(domain)
    liveness = graph_liveness(getattr(args, "graph_file", None) or GRAPH_FILE, "real", graph.names(),
                              getattr(args, "budgets", None))
    run = SupervisedGraph(graph, liveness, domain.env, out, lambda node: _restarter(node, domain, out, watch.base),
                          time.monotonic, log=lambda s: print("  " + s, flush=True))
    RunObserver(watch.base.node, run.monitor)            # arrivals and typed diagnostics to the monitor
    reference = None             # the reference sim_node: outside the loop, not supervised
    interrupted = watch.interrupted
    restore_signals = redirect_stop_signals(interrupted.append)     # Ctrl-C, SIGTERM, SIGHUP: a graceful stop
    reason = None
    t_start = None
    try:
        run.start()
        # before the start a node's exit fails the pre-flight (nothing restarts it: nothing to resume)
        checks = preflight(args, watch, run.supervisor.processes(), path, args.preflight_timeout)
        for c in checks:
            print(f"  pre-flight {c.name:11s} {'ok  ' if c.ok else 'FAIL'} {c.message}", flush=True)
        (out / "preflight.json").write_text(json.dumps([c.__dict__ for c in checks], indent=1) + "\n")
        failed = [c.message for c in checks if not c.ok]
        if interrupted:
            failed.append(f"interrupted ({interrupted[0]}) during the pre-flight")
        if failed:
            raise PreflightError(failed)
        if args.reference_sim:
            reference = reference_sim_node(args, watch.poses[-1][1:]).start(domain.env, out)
        recorded = ("/frog/odom", "/frog/primitive", "/frog/planner/status")
        watch.base.wait(lambda: watch.base.subscribed("recorder", recorded), 30,
                        "the recorder subscribed to the loop's topics", run.supervisor.processes())
        watch.base.start_planner()
        t_start = time.monotonic()
        run.monitor.restart(t_start, t_start)                  # the pre-flight does not count as silence
        print(f"  {name}: following on the real robot (at most {args.duration:.0f} s; Ctrl-C or "
              f"/frog/stop stops)", flush=True)
        while reason is None:
            watch.spin(0.05)
            if interrupted:
                reason = interrupted[0]
            elif watch.stops:
                reason = "stop received on /frog/stop"
            elif watch.base.state == watch.base.Status.STATE_GOAL_REACHED:
                reason = "goal reached"
            elif time.monotonic() - t_start > args.duration:
                reason = f"duration {args.duration:g} s"
            else:
                reason = run.poll()
        watch.stop_all()
        t_stop = time.monotonic()
        print(f"  {name}: stopped ({reason})", flush=True)
        watch.spin(1.0)
    finally:
        if reason is None:
            watch.stop_all()
        restore_signals()
        run.supervisor.stop_all()
        if reference is not None and reference.running():
            reference.stop()
        watch.close()
        domain.release()
    summary = dict(run.supervisor.summary(), liveness_verdicts=run.verdicts)
    return real_report(args, name, out, settings, path_settings, reason, t_stop - t_start, checks, summary, earlier)


def real_report(args, name, out, settings, path_settings, reason, wall, checks, supervision=None,
                earlier=frozenset()) -> dict:
    """The twin's report of a real run, on the tracked pose (the only trajectory there is)."""

    from frog_twin.core.twin_recording import readable_files, run_files
    files = run_files(out / "recording", earlier)     # not an earlier run's files in the same folder
    if not files:
        raise RuntimeError(f"no recording in {out / 'recording'}; see {out}/recorder.log")
    files = readable_files(files, out / "recovered")    # a killed recorder's file, recovered
    rec = read_twin_recording(files)
    predicted = rec.truth         # the reference sim_node's frog/sim/odom, if it ran
    rec.truth = rec.tracked       # no ground truth on the real robot: the camera's track is the trajectory
    metrics = twin_report.run_metrics(rec, name)
    if len(predicted) > 1 and rec.path is not None:
        from frog_twin.core.metrics import distance_to_polyline
        start = metrics["start_time_s"]
        p = predicted[predicted[:, 0] >= start]
        k = np.searchsorted(rec.tracked[:, 0], p[:, 0]).clip(0, len(rec.tracked) - 1)
        metrics["reference_prediction"] = {
            "n": int(len(p)), "mean_distance_to_path_m": float(distance_to_polyline(p[:, 1:3], rec.path).mean())
            if len(p) else None,
            "mean_distance_to_tracked_m": float(np.hypot(*(p[:, 1:3] - rec.tracked[k, 1:3]).T).mean())
            if len(p) else None, "source": "sim_node beside the robot (--reference-sim), not in the loop"}
    metrics["vision"] = {"n": int(len(rec.tracked)), "rate_hz": float(
        len(rec.tracked) / max(rec.tracked[-1, 0] - rec.tracked[0, 0], 1e-9)) if len(rec.tracked) > 1 else 0.0}
    metrics.update(mode="real", trajectory="tracked (camera + tracker); no ground truth", stop_reason=reason,
                   wall_time_s=wall, recording=[str(f) for f in files], supervision=supervision,
                   preflight=[c.__dict__ for c in checks],
                   settings={"planner": settings.as_dict(), "path": path_settings.as_dict(),
                             "robot_port": str(args.robot_port), "camera": str(args.camera),
                             "camera_info": str(args.camera_info) if args.camera_info else None,
                             "tank_calibration": str(args.tank_calibration) if args.tank_calibration else None,
                             "tag_offset": str(args.tag_offset) if args.tag_offset else None,
                             "tag_offset_params": getattr(args, "tag_offset_params", None)})
    metrics["units"]["time"] = "s (system clock)"
    w = settings.weights
    twin_report.plot_run(rec, metrics, out.parent / f"{name}.png", weights=(w.distance, w.heading, w.progress))
    metrics["plot"] = str(out.parent / f"{name}.png")
    frames = twin_report.write_video(rec, out.parent / f"{name}.mp4", _real_projector(args, rec))
    metrics["video"] = str(out.parent / f"{name}.mp4") if frames else None
    (out.parent / f"{name}.json").write_text(json.dumps(metrics, indent=1, default=float) + "\n")
    return metrics


def _real_projector(args, rec):
    """tank points -> preview pixels through the real camera's calibration files."""
    if rec.camera_info is None or not rec.preview:
        return None
    import cv2
    import numpy as np
    from frog_vision.core.camera_model import CameraModel
    from frog_vision.core.tank_calibration import CameraPose, TankCalibration
    info = rec.camera_info
    camera = CameraModel.from_camera_info({"width": info.width, "height": info.height, "k": list(info.k),
                                           "d": list(info.d), "distortion_model": info.distortion_model})
    pose = TankCalibration.from_yaml(args.tank_calibration).pose if args.tank_calibration else CameraPose.overhead(0.8)
    h = cv2.imdecode(np.frombuffer(rec.preview[0][1], np.uint8), cv2.IMREAD_COLOR).shape[0]
    scale = h / info.height
    return lambda pts: pose.project(camera, pts) * scale
