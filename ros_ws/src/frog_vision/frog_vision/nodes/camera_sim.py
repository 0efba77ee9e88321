"""``camera_sim``: the overhead camera of the digital twin.

Subscribes to the simulator's ground truth (``frog/sim/odom``: COM pose in ``tank``, body
twist) and rod network (``frog/sim/shape``), and publishes rendered frames on
``camera/image_raw`` (bgr8) with ``camera/camera_info``, at ``fps`` on the node clock (the
simulated time with ``use_sim_time``), stamped with the capture time. The robot is drawn
where the odometry says it is at that time (extrapolated with its twist from the last
message), with the shape's outline carried rigidly from the shape's own time.

Fault hooks (live parameters, set by the twin's fault injector with SetParameters):
``fault_freeze`` publishes the last rendered frame again (the same bytes) with fresh stamps,
as a hung driver does; ``fault_stopped`` publishes no frames and no camera_info;
``drop_probability`` loses frames at random; ``occlusion_start_s`` / ``occlusion_duration_s``
hide the robot under an occluder for a span of node-clock time.
"""
from __future__ import annotations

import bisect
import collections
import math
import sys
import time

import numpy as np
from nav_msgs.msg import Odometry
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import CameraInfo, Image
from soft_robot_common import (ConfigurationError, MessageGate, NodeDiagnostics, Param, declare_parameters,
                               params_from_dataclass, run_node)
from soft_robot_common.diagnostics import OK, WARN
from visualization_msgs.msg import Marker

from frog_vision.core.camera_model import CameraModel
from frog_vision.core.pose import compose_offset
from frog_vision.core.renderer import AUTHORS_CORNER_JITTER_PX, Occluder, RenderSettings, TankRenderer
from frog_vision.core.robot_shape import RobotShape, frog_outline, shape_from_segments
from frog_vision.core.tank_calibration import Board
from frog_vision.nodes.common import load_camera, load_camera_pose
from frog_vision.nodes.messages import array_to_image, camera_info_msg, s_to_stamp, stamp_to_s
from frog_vision.nodes.settings import CAMERA_PARAMS, TAG_PARAMS
from frog_common.se2 import twist_arc, yaw_of
from frog_common.settings import from_params

_RENDER_PARAMS = ("exposure", "blur_samples", "noise_sigma", "brightness", "lighting", "corner_jitter_px",
                  "drop_probability", "seed")
# a simulated camera is not ideal by default: the authors' measured pose noise at rest
PARAMS = TAG_PARAMS + CAMERA_PARAMS + params_from_dataclass(
    RenderSettings, names=_RENDER_PARAMS, defaults=RenderSettings(corner_jitter_px=AUTHORS_CORNER_JITTER_PX)) + [
    Param("board_file", "", "calibration board drawn in the tank (YAML); empty = the default board"),
    Param("fps", 30.0, "frame rate in node-clock time [Hz]", min=1.0, max=240.0),
    Param("frame_id", "camera", "frame of the images"),
    Param("tag_yaw", 0.0, "yaw of the tag on the body [rad], as mounted (the authors' robot's was turned by about "
          "+5 deg: the hardware replay draws it so; a tracker without offset_yaw then reports heading + tag_yaw)",
          min=-math.pi, max=math.pi),
    Param("occlusion_start_s", -1.0, "hide the robot under an occluder from this node-clock time [s]; < 0 = never "
          "(live; on the system clock an epoch time)", min=-1.0, max=1e10, live=True),
    Param("occlusion_duration_s", 1.0, "for this long [s] (live)", min=0.0, max=1e6, live=True),
    Param("fault_freeze", False, "fault: publish the last rendered frame again (the same bytes) with fresh stamps, "
          "like a hung camera driver (live)", live=True),
    Param("fault_stopped", False, "fault: publish no frames and no camera_info, like a dead camera (live)",
          live=True),
]


class CameraSimNode(Node):
    NODE_NAME = "camera_sim"

    def __init__(self):
        super().__init__("camera_sim")
        p = declare_parameters(self, PARAMS, on_change=self._on_parameters)
        self.cfg = p
        camera = load_camera(p["camera_info_file"]) or CameraModel.realsense_640x480()
        pose = load_camera_pose(p["tank_calibration_file"])
        try:
            board = Board.from_yaml(p["board_file"] or None)
            settings = from_params(RenderSettings, p)
            self.renderer = TankRenderer(camera, pose, settings, board)
        except (OSError, ValueError) as exc:
            raise ConfigurationError(str(exc)) from exc
        self.camera = camera
        qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        self.image_pub = self.create_publisher(Image, "camera/image_raw", QoSProfile(depth=2))
        self.info_pub = self.create_publisher(CameraInfo, "camera/camera_info", QoSProfile(depth=2))
        self.create_subscription(Odometry, "frog/sim/odom", self.on_odom, qos)
        self.create_subscription(Marker, "frog/sim/shape", self.on_shape, qos)
        self.odom = collections.deque(maxlen=200)          # (t, pose, twist)
        self.shape: RobotShape | None = None
        c = frog_outline().ring_centre      # until the first shape arrives
        self.tag_offset = (float(c[0]), float(c[1]), p["tag_yaw"])   # the tag's pose on the body
        self.frames = 0
        self.skipped = 0
        self.dropped = 0                 # frames lost on purpose (drop_probability)
        self.repeated = 0                # frames published again by fault_freeze
        self.last_image = None           # the last rendered frame (fault_freeze repeats it)
        self._diag_refused = 0
        self.refused = 0                 # messages refused by the common rule (non-finite, unstamped)
        self.last_refusal = ""
        self.gate = MessageGate(self)    # logs once a second per input and problem (a new field at once)
        self.next_capture = None
        self.waiting_logged = False
        self.busy_s = 0.0
        self.render_s = 0.0
        self.cpu_s = 0.0
        self._diag_frames, self._diag_busy, self._diag_wall = 0, 0.0, time.monotonic()
        self.create_timer(0.5 / p["fps"], self.tick)
        # diagnostics on the wall clock (NodeDiagnostics): they report the node's own load
        self.diagnostics = NodeDiagnostics(self, "camera simulator", self._diagnostics, hardware_id="camera_sim")
        self.get_logger().info(f"rendering {camera.width}x{camera.height} at {p['fps']:g} fps "
                               f"(tag {p['tag_family']} id {p['tag_id']}, noise {p['noise_sigma']:g})")

    def _on_parameters(self, changed: dict) -> None:
        if "drop_probability" in changed:
            self.renderer.settings = self.renderer.settings.replace(drop_probability=changed["drop_probability"])
        for name, what in (("fault_freeze", "repeating the last frame with fresh stamps"),
                           ("fault_stopped", "publishing no frames and no camera_info")):
            if name in changed:
                if changed[name]:
                    self.get_logger().warn(f"fault injected: {name}: {what}")
                else:
                    self.get_logger().info(f"fault cleared: {name}")

    def _refuse(self, what: str, msg) -> bool:
        """Log and count ``msg`` if the common rule refuses it (True: refused)."""
        problem = self.gate.problem(msg)
        if problem is None:
            return False
        self.refused += 1
        self.last_refusal = f"{what} refused: {problem}"
        if self.gate.should_log(what, problem):
            self.get_logger().warn(self.last_refusal)
        return True

    def on_odom(self, msg: Odometry) -> None:
        if self._refuse("frog/sim/odom", msg):
            return
        p = msg.pose.pose
        tw = msg.twist.twist
        self.odom.append((stamp_to_s(msg.header.stamp), np.array([p.position.x, p.position.y, yaw_of(p.orientation)]),
                          np.array([tw.linear.x, tw.linear.y, tw.angular.z])))

    def on_shape(self, msg: Marker) -> None:
        if self._refuse("frog/sim/shape", msg):
            return
        if msg.type != Marker.LINE_LIST or len(msg.points) < 6 or len(msg.points) % 2:
            self.get_logger().error(f"ignored shape: expected a LINE_LIST with an even number of points, got type "
                                    f"{msg.type} with {len(msg.points)} points")
            return
        if not self.odom:
            return
        t = stamp_to_s(msg.header.stamp)
        ref = min(self.odom, key=lambda o: abs(o[0] - t))     # the COM pose at the shape's time
        if abs(ref[0] - t) > 0.1:
            return
        pts = np.array([[q.x, q.y] for q in msg.points])
        try:
            world = shape_from_segments(pts.reshape(-1, 2, 2))
        except ValueError as exc:
            self.get_logger().error(f"ignored shape: {exc}")
            return
        self.shape = _to_local(world, ref[1])
        c = self.shape.ring_centre
        self.tag_offset = (float(c[0]), float(c[1]), self.cfg["tag_yaw"])

    def tick(self) -> None:
        """Render every frame whose capture time (a grid of 1/fps in node-clock time) has come.

        The simulator's /clock advances in steps (its publication period), so frames are
        taken on the exact grid rather than at the timer's firing times; a frame more than
        two periods late is skipped (counted), never rendered late with a stale stamp. A frame
        waits until odometry at or after its capture time has arrived, and the pose is
        interpolated between the two odometry messages around it (exact ground truth even
        when the odometry is delayed)."""
        t = self.get_clock().now().nanoseconds * 1e-9
        if not self.odom:
            if not self.waiting_logged:
                self.get_logger().info("waiting for frog/sim/odom")
                self.waiting_logged = True
            return
        period = 1.0 / self.cfg["fps"]
        if self.next_capture is None or t < self.next_capture - 10 * period:   # start, or time jumped back
            self.next_capture = math.ceil(t / period) * period
        if t - self.next_capture > 2 * period:
            missed = int((t - self.next_capture) / period) - 1
            self.skipped += missed
            self.next_capture += missed * period
        while self.next_capture <= t + 1e-9 and self.next_capture <= self.odom[-1][0] + 1e-9:
            self.capture(self.next_capture)
            self.next_capture += period

    def capture(self, t: float) -> None:
        if self.cfg["fault_stopped"]:
            return
        pose_now, twist = _interpolate(self.odom, t)
        if self.renderer.should_drop():
            self.dropped += 1
            return
        if self.cfg["fault_freeze"] and self.last_image is not None:
            stamp = s_to_stamp(t)
            self.image_pub.publish(array_to_image(self.last_image, stamp, self.cfg["frame_id"]))
            self.info_pub.publish(camera_info_msg(self.camera, stamp, self.cfg["frame_id"]))
            self.frames += 1
            self.repeated += 1
            return
        occ = []
        start = self.cfg["occlusion_start_s"]
        if start >= 0 and start <= t < start + self.cfg["occlusion_duration_s"]:
            tag, _ = compose_offset(pose_now, self.tag_offset)
            occ = [Occluder(tag[0], tag[1], 0.07)]
        w0 = time.perf_counter()
        c0 = time.process_time()
        img = self.renderer.render(pose_now, twist, self.shape, self.tag_offset, occ)
        self.render_s += time.perf_counter() - w0
        stamp = s_to_stamp(t)
        self.last_image = img
        self.image_pub.publish(array_to_image(img, stamp, self.cfg["frame_id"]))
        self.info_pub.publish(camera_info_msg(self.camera, stamp, self.cfg["frame_id"]))
        self.frames += 1
        self.busy_s += time.perf_counter() - w0
        self.cpu_s += time.process_time() - c0

    def _diagnostics(self):
        wall = time.monotonic()
        frames, busy = self.frames - self._diag_frames, self.busy_s - self._diag_busy
        span = wall - self._diag_wall
        self._diag_frames, self._diag_busy, self._diag_wall = self.frames, self.busy_s, wall
        recent_refusal = self.refused > self._diag_refused
        self._diag_refused = self.refused
        level = OK if self.odom and frames and not recent_refusal else WARN
        faults = [n for n in ("fault_stopped", "fault_freeze") if self.cfg[n]]
        if faults:
            level, text = WARN, "fault injected: " + ", ".join(faults)
        elif recent_refusal:
            text = self.last_refusal
        elif not self.odom:
            text = "waiting for frog/sim/odom"
        else:
            text = "rendering" if frames else "no frame rendered: waiting for odometry at the capture times"
        return level, text, {
            "frames": self.frames, "frames_per_wall_s": f"{frames / span:.1f}" if span > 0 else "nan",
            "render_publish_ms": f"{busy / frames * 1e3:.2f}" if frames else "nan",
            "cpu_ms_mean": f"{self.cpu_s / max(self.frames, 1) * 1e3:.2f}",
            "render_ms_mean": f"{self.render_s / max(self.frames, 1) * 1e3:.2f}",
            "frames_skipped": self.skipped, "frames_dropped": self.dropped, "frames_repeated": self.repeated,
            "shape_received": self.shape is not None, "messages_refused": self.refused,
            "ready": self.frames > 0}


def _interpolate(odom, t: float):
    """Pose and twist at ``t`` between the odometry samples around it (before the first one:
    moved back with its twist)."""
    times = [o[0] for o in odom]
    i = bisect.bisect_right(times, t + 1e-9)
    if i == 0:
        t0, pose, twist = odom[0]
        return twist_arc(pose, twist, max(t - t0, -0.2)), twist
    t0, p0, v0 = odom[i - 1]
    if i == len(odom) or abs(t - t0) < 1e-9:
        return twist_arc(p0, v0, min(t - t0, 0.2)), v0
    t1, p1, v1 = odom[i]
    w = (t - t0) / (t1 - t0)
    d = p1 - p0
    d[2] = math.remainder(d[2], 2 * math.pi)
    return p0 + w * d, v0 + w * (v1 - v0)


def _to_local(world: RobotShape, com_pose) -> RobotShape:
    """A tank-frame shape expressed in the body frame at ``com_pose``."""
    c, s = np.cos(com_pose[2]), np.sin(com_pose[2])
    rot = np.array([[c, -s], [s, c]])            # body -> tank; row vectors: (p - t) @ rot
    t = np.asarray(com_pose[:2])
    return RobotShape((world.ring - t) @ rot, (world.limbs - t) @ rot)


def main(args=None) -> int:
    return run_node(CameraSimNode, args)


if __name__ == "__main__":
    sys.exit(main())
