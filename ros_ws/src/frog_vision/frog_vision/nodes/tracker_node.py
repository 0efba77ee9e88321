"""``tracker_node``: the robot's pose and velocity from its AprilTag.

Subscribes to ``camera/image_raw`` and ``camera/camera_info`` (or a ``camera_info_file``),
publishes ``frog/pose`` (PoseStamped) and ``frog/odom`` (Odometry: pose in ``tank``, body
twist in ``frog``, covariances filled), stamped with the image's capture time; an
annotated ``frog/tracker/debug_image`` when ``publish_debug_image``; and ``diagnostics``
(detection rate, capture-to-publish latency, dropped frames, reprojection error). While the
tag is not seen, predictions are published for up to ``coast_timeout`` after the last
measurement, stamped with each new frame's capture time; after that nothing is published (no
stale poses) and the diagnostics say so.

Frozen camera: a driver that hangs may repeat its last image with fresh stamps, while a real
sensor (and camera_sim, whose frames carry noise) never delivers two byte-identical frames.
No copy of the previous frame is ever posed (a CRC-32 of the bytes,
:mod:`frog_vision.core.frame_check`; diagnostics ``repeated_frames_skipped``); from the
``frozen_frames``-th identical frame in a row a warning is logged once and the diagnostics
report ERROR "camera frozen" (nothing is published: pose, odometry, tf); tracking resumes
with the first frame that differs. A frame whose stamp does not advance past the previous
frame's is refused.

Kick inputs: with ``kick_topic`` set (default ``frog/bridge/sent``, the bridge's record of
every limb firing written to the robot, soft_robot_interfaces/LimbActivation stamped at the
write) each firing is given to the filter, which then follows the power stroke for
``kick_window`` and uses a low process noise with drag while the robot coasts (see
``frog_vision.core.state_filter``). Until the first firing arrives, or with
``kick_topic`` empty, the filter runs on ``accel_noise`` / ``yaw_accel_noise`` alone.

``estimator:=frame_difference`` replaces the filter with the paper's own estimate: each frame's
raw pose, and velocities as the difference to the previous frame
(:mod:`frog_vision.core.frame_difference`). It is what the authors' planner saw, for replaying
their experiments; it is far noisier than the filter.
"""
from __future__ import annotations

import collections
import sys

import cv2
import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped, TransformStamped
from nav_msgs.msg import Odometry
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import CameraInfo, Image
from soft_robot_common import (ConfigurationError, MessageGate, Param, declare_parameters, params_from_dataclass,
                                run_node)
from soft_robot_interfaces.msg import LimbActivation

from frog_vision.core.detection import DetectorSettings
from frog_vision.core.frame_check import FrozenFrameDetector
from frog_vision.core.pose import PoseSettings
from frog_vision.core.state_filter import FilterSettings
from frog_vision.core.tracker import ESTIMATORS, Tracker
from frog_vision.nodes.common import load_camera, load_camera_pose
from frog_vision.nodes.messages import array_to_image, image_to_array, model_from_camera_info, stamp_to_s
from frog_vision.nodes.settings import CAMERA_PARAMS, TAG_PARAMS
from frog_common.se2 import set_yaw
from frog_common.settings import from_params

# the filter's settings that a user tunes (the gates and initial uncertainties stay the core's)
_FILTER_PARAMS = ("accel_noise", "yaw_accel_noise", "kick_window", "kick_delay", "kick_accel_noise",
                  "kick_yaw_accel_noise", "coast_accel_noise", "coast_yaw_accel_noise", "coast_drag_time",
                  "coast_yaw_drag_time", "coast_timeout", "reset_timeout")
PARAMS = TAG_PARAMS + CAMERA_PARAMS + [
    Param("world_frame", "tank", "frame of the poses"),
    Param("body_frame", "frog", "robot frame (child frame of the odometry)"),
] + params_from_dataclass(PoseSettings, names=("offset_x", "offset_y", "offset_yaw")) + params_from_dataclass(
    DetectorSettings, names=("decimate", "threads", "refine_edges")) + [
    Param("search_window", 3.0, "search around the predicted tag, in tag sizes; 0 = whole image", min=0.0, max=50.0),
] + params_from_dataclass(PoseSettings, names=("corner_sigma_px",)) + [
    Param("estimator", "filter", "state from the tag poses: 'filter' (Kalman filter with kick inputs) or "
          "'frame_difference' (the paper's tracker: the raw pose, velocities as differences of consecutive frames)",
          choices=ESTIMATORS),
    Param("kick_topic", "frog/bridge/sent", "limb firings (LimbActivation) fed to the filter as kick inputs; "
          "empty = none"),
] + params_from_dataclass(FilterSettings, names=_FILTER_PARAMS) + [
    Param("publish_debug_image", False, "publish frog/tracker/debug_image (annotated frames)", live=True),
    Param("publish_tf", True, "publish the tracked pose on tf as world_frame -> body_frame"),
    Param("frozen_frames", 3, "this many byte-identical frames in a row (the first included) mean a frozen camera: "
          "nothing is published from them until the frames change", min=2, max=1000, live=True),
]


class TrackerNode(Node):
    NODE_NAME = "tracker_node"

    def __init__(self):
        super().__init__("tracker_node")
        p = declare_parameters(self, PARAMS, validate=self._validate, on_change=self._apply)
        self.cfg = dict(p)
        self.fixed_camera = load_camera(p["camera_info_file"])
        self.camera_pose = load_camera_pose(p["tank_calibration_file"])
        if not p["tank_calibration_file"]:
            self.get_logger().warn("no tank_calibration_file: assuming the default camera pose 0.8 m over the tank")
        try:
            self.detector = from_params(DetectorSettings, p, family=p["tag_family"], tag_ids=(p["tag_id"],))
            self.pose_settings = from_params(PoseSettings, p)
            self.filter_settings = self._filter_settings(p)
        except ValueError as exc:
            raise ConfigurationError(str(exc)) from exc
        self.tracker: Tracker | None = None
        self.gate = MessageGate(self)     # non-finite, unstamped or oversized inputs are refused
        self.last_kick: float | None = None       # stamp of the last limb firing [s]
        if self.fixed_camera is not None:
            self._make_tracker(self.fixed_camera)
        # keep the last 2 only: a busy tracker skips frames instead of working through a growing
        # backlog of old ones. Reliable: best-effort loses most 0.9 MB frames on the way (a
        # lost UDP fragment drops the whole sample), and a keep-last writer never blocks on it.
        sensor = QoSProfile(depth=2, reliability=ReliabilityPolicy.RELIABLE)
        self.create_subscription(Image, "camera/image_raw", self.on_image, sensor)
        self.create_subscription(CameraInfo, "camera/camera_info", self.on_info, sensor)
        if p["kick_topic"]:
            self.create_subscription(LimbActivation, p["kick_topic"], self.on_kick,
                                     QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
        self.pose_pub = self.create_publisher(PoseStamped, "frog/pose", 10)
        self.odom_pub = self.create_publisher(Odometry, "frog/odom", 10)
        self.debug_pub = self.create_publisher(Image, "frog/tracker/debug_image", 2)
        self.diag_pub = self.create_publisher(DiagnosticArray, "diagnostics", 10)
        self.tf_pub = None
        if p["publish_tf"]:
            try:
                from tf2_msgs.msg import TFMessage
            except ImportError:
                self.get_logger().warning("tf2_msgs is not installed: not publishing tf")
            else:
                self._TFMessage = TFMessage
                self.tf_pub = self.create_publisher(TFMessage, "tf", 100)
        self.window = collections.deque(maxlen=90)        # (detected, latency_s, compute_s, residual)
        self.frames = self.dropped = self.bad_frames = 0
        self.frozen = FrozenFrameDetector(p["frozen_frames"])
        self._frozen_from, self._frozen_refused = "", 0     # state before a freeze; frames refused in it
        self.repeated_skipped = 0     # copies of the previous frame, before a frozen verdict: not posed
        self.last_stamp = None
        self.period = None
        self.state_name = "waiting for images"
        self.state_changed = False
        self.last_error = ""
        self._logged_error = None
        # diagnostics every wall second (also on simulated time), and at each state change
        self.create_timer(1.0, self.publish_diagnostics, clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.get_logger().info(f"tracking {p['tag_family']} id {p['tag_id']} ({p['tag_size'] * 1e3:g} mm)")

    @staticmethod
    def _filter_settings(p) -> FilterSettings:
        return from_params(FilterSettings, {k: p[k] for k in _FILTER_PARAMS})

    def _validate(self, values: dict) -> str | None:
        try:
            self._filter_settings(values)
        except ValueError as exc:
            return str(exc)
        return None

    def _apply(self, changed: dict) -> None:
        self.cfg.update(changed)
        if "frozen_frames" in changed:
            self.frozen.frozen_frames = int(changed["frozen_frames"])
        self.filter_settings = self._filter_settings(self.cfg)
        if self.tracker is not None:
            self.tracker.filter.settings = self.filter_settings

    def _make_tracker(self, camera) -> None:
        self.tracker = Tracker(camera, self.camera_pose, self.detector, self.pose_settings, self.filter_settings,
                               self.cfg["search_window"], self.cfg["estimator"])
        if self.last_kick is not None:            # a firing before the first camera_info still counts
            self.tracker.kick(self.last_kick)

    def on_kick(self, msg: LimbActivation) -> None:
        if self.gate.refused(self.cfg["kick_topic"], msg):
            return
        if not msg.limbs:                         # nothing was heated
            return
        stamp = stamp_to_s(msg.header.stamp)
        if not np.isfinite(stamp) or stamp <= 0:
            self._error(f"ignored limb firing with stamp {stamp!r}")
            return
        if self.last_kick is None:
            self.get_logger().info(f"kick inputs from {self.cfg['kick_topic']}: filtering with the stroke model")
        self.last_kick = stamp
        self.get_logger().debug(f"kick at {stamp:.3f} s: limbs {list(msg.limbs)}")
        if self.tracker is not None:
            self.tracker.kick(stamp)

    def _error(self, text: str) -> None:
        if text != self._logged_error:            # a stream of the same bad frames is logged once
            self.get_logger().error(text)
        self._logged_error = self.last_error = text
        self.bad_frames += 1

    def on_info(self, msg: CameraInfo) -> None:
        if self.gate.refused("camera/camera_info", msg, stamped=False):    # its stamp is not used
            return
        if self.fixed_camera is not None:
            return
        try:
            model = model_from_camera_info(msg)
        except ValueError as exc:
            self._error(f"ignored camera_info: {exc}")
            return
        if self.tracker is None:
            self._make_tracker(model)
            self.get_logger().info(f"camera model from camera_info: {model.width}x{model.height}")
        elif not (np.array_equal(model.K, self.tracker.camera.K) and np.array_equal(model.D, self.tracker.camera.D)
                  and (model.width, model.height) == (self.tracker.camera.width, self.tracker.camera.height)):
            self.tracker.set_camera(model)
            self.get_logger().info("camera model changed")

    def on_image(self, msg: Image) -> None:
        if self.gate.refused("camera/image_raw", msg):
            return
        stamp = stamp_to_s(msg.header.stamp)
        if self.tracker is None:
            self._error("no camera_info received yet: cannot use images")
            return
        try:
            img = image_to_array(msg)
            self.tracker.camera.check_image(img)
        except ValueError as exc:
            self._error(f"refused bad frame: {exc}")
            return
        if self.last_stamp is not None:
            gap = stamp - self.last_stamp
            if gap <= 0:
                self._error(f"frame stamped {stamp:.3f} s is not newer than the last ({self.last_stamp:.3f} s)")
                return
            self.period = gap if self.period is None else min(0.95 * self.period + 0.05 * gap, gap * 1.5)
            if self.period and gap > 1.5 * self.period:
                self.dropped += int(round(gap / self.period)) - 1
        self.last_stamp = stamp
        self.frames += 1
        if self.frozen.check(msg.data):
            # the same picture again with a fresh stamp: a pose from it would be stale
            if self.state_name != "frozen":
                self.get_logger().warn(f"camera frozen: {self.frozen.run} identical frames in a row (same bytes, "
                                       f"fresh stamps); no pose, odometry or tf from them until the frames change")
                self.state_name, self._frozen_from, self._frozen_refused = "frozen", self.state_name, 0
                self.publish_diagnostics()
            self._frozen_refused += 1
            return
        if self.frozen.repeated:
            # a copy before the frozen verdict: no new observation, and its pose would be stale content at
            # a fresh stamp (the twin fired a kick on one under load, docs/faults.md); dropped, counted
            self.repeated_skipped += 1
            return
        if self.state_name == "frozen":
            self.get_logger().info(f"camera frames change again after {self._frozen_refused} frozen frame(s): "
                                   f"tracking resumes")
            self.state_name = self._frozen_from
        self._logged_error = None                 # a good frame: log the next problem again
        res = self.tracker.process(img, stamp)
        before = self.state_name
        if res.state is not None:
            self.publish_state(msg.header.stamp, res.state)
            self.state_name = "coasting" if res.state.coasting else "tracking"
        else:
            # lost (ERROR) once it has been tracked, also after the filter's reset
            self.state_name = "lost" if self.tracker.n_measured > 0 else "searching"
        if self.state_name != before:
            why = f" ({res.reason})" if res.reason and self.state_name != "tracking" else ""
            if self.state_name == "lost":
                self.get_logger().warn(f"tag lost{why}: odometry stopped")
            else:
                self.get_logger().info(f"tag {self.state_name}{why}")
            self.state_changed = True
        latency = self.get_clock().now().nanoseconds * 1e-9 - stamp
        self.window.append((res.measurement is not None, latency, res.compute_s,
                            res.measurement.residual_px if res.measurement is not None else np.nan))
        if self.state_changed:
            self.publish_diagnostics()          # say it at once, not at the next 1 s tick
            self.state_changed = False
        if self.cfg["publish_debug_image"]:
            self.debug_pub.publish(array_to_image(self._annotate(img, res), msg.header.stamp, msg.header.frame_id))

    def publish_state(self, stamp, st) -> None:
        pose = PoseStamped()
        pose.header.stamp = stamp
        pose.header.frame_id = self.cfg["world_frame"]
        pose.pose.position.x, pose.pose.position.y = float(st.pose[0]), float(st.pose[1])
        set_yaw(pose.pose.orientation, float(st.pose[2]))
        self.pose_pub.publish(pose)
        odom = Odometry()
        odom.header = pose.header
        odom.child_frame_id = self.cfg["body_frame"]
        odom.pose.pose = pose.pose
        odom.twist.twist.linear.x, odom.twist.twist.linear.y = float(st.body_velocity[0]), float(st.body_velocity[1])
        odom.twist.twist.angular.z = float(st.body_velocity[2])
        odom.pose.covariance = _planar_covariance(st.pose_covariance)
        odom.twist.covariance = _planar_covariance(st.twist_covariance)
        self.odom_pub.publish(odom)
        if self.tf_pub is not None:
            tf = TransformStamped()
            tf.header = pose.header
            tf.child_frame_id = self.cfg["body_frame"]
            tf.transform.translation.x, tf.transform.translation.y = pose.pose.position.x, pose.pose.position.y
            tf.transform.rotation = pose.pose.orientation
            self.tf_pub.publish(self._TFMessage(transforms=[tf]))

    def _annotate(self, img, res):
        out = img.copy() if img.ndim == 3 else cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
        if res.corners is not None:
            cv2.polylines(out, [np.round(res.corners * 4).astype(np.int32)], True, (0, 0, 255), 1, cv2.LINE_AA, 2)
        text = "lost" if res.state is None else (
            f"x {res.state.pose[0]:+.3f} y {res.state.pose[1]:+.3f} th {np.degrees(res.state.pose[2]):+.1f} "
            f"v {res.state.body_velocity[0] * 100:+.1f} cm/s w {np.degrees(res.state.body_velocity[2]):+.0f} deg/s")
        cv2.putText(out, text, (8, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 255), 1, cv2.LINE_AA)
        return out

    def publish_diagnostics(self) -> None:
        w = list(self.window)
        rate = float(np.mean([d for d, *_ in w])) if w else float("nan")
        lat = float(np.median([x[1] for x in w])) if w else float("nan")
        comp = float(np.median([x[2] for x in w])) if w else float("nan")
        res = [x[3] for x in w if np.isfinite(x[3])]
        if self.state_name in ("tracking",):
            level, message = DiagnosticStatus.OK, "tracking"
        elif self.state_name == "coasting":
            level, message = DiagnosticStatus.WARN, "tag not seen: coasting on the prediction"
        elif self.state_name == "lost":
            level, message = DiagnosticStatus.ERROR, "tag lost: odometry stopped"
        elif self.state_name == "frozen":
            level, message = DiagnosticStatus.ERROR, (f"camera frozen: {self.frozen.run} identical frames in a row; "
                                                      f"odometry stopped")
        else:
            level, message = DiagnosticStatus.WARN, self.state_name
        status = DiagnosticStatus(name=f"{self.get_name()}: tag tracking", hardware_id="camera", level=level,
                                  message=message)
        status.values = [KeyValue(key="detection_rate", value=f"{rate:.3f}"),
                         KeyValue(key="latency_ms", value=f"{lat * 1e3:.1f}"),
                         KeyValue(key="compute_ms", value=f"{comp * 1e3:.2f}"),
                         KeyValue(key="frames", value=str(self.frames)),
                         KeyValue(key="dropped_frames", value=str(self.dropped)),
                         KeyValue(key="bad_frames", value=str(self.bad_frames)),
                         KeyValue(key="frozen", value=str(self.state_name == "frozen").lower()),
                         KeyValue(key="frozen_frames_refused", value=str(self.frozen.frozen_total)),
                         KeyValue(key="repeated_frames_skipped", value=str(self.repeated_skipped)),
                         KeyValue(key="reprojection_error_px", value=f"{np.median(res):.3f}" if res else "nan"),
                         KeyValue(key="last_error", value=self.last_error)]
        msg = DiagnosticArray(status=[status])
        msg.header.stamp = self.get_clock().now().to_msg()
        self.diag_pub.publish(msg)


def _planar_covariance(c3) -> list:
    """6x6 row-major covariance (x, y, z, roll, pitch, yaw) from a planar 3x3 one; the
    unobserved z, roll and pitch get a large variance."""
    c = np.zeros((6, 6))
    idx = [0, 1, 5]
    c[np.ix_(idx, idx)] = c3
    for i in (2, 3, 4):
        c[i, i] = 1e6
    return [float(v) for v in c.ravel()]


def main(args=None) -> int:
    return run_node(TrackerNode, args)


if __name__ == "__main__":
    sys.exit(main())
