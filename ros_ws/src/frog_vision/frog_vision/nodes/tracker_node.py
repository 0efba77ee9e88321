"""``tracker_node``: the robot's pose and velocity from its AprilTag.

Subscribes to ``camera/image_raw`` and ``camera/camera_info`` (or a ``camera_info_file``),
publishes ``frog/pose`` (PoseStamped) and ``frog/odom`` (Odometry: pose in ``tank``, body
twist in ``frog``, covariances filled), stamped with the image's capture time; for every
frame ``frog/tracker/state`` (soft_robot_interfaces/TrackerState, same stamp: searching,
tracking, coasting, lost or frozen, and the capture stamp of the newest frame in which the tag
was seen); an annotated ``frog/tracker/debug_image`` when ``publish_debug_image``; and
``diagnostics`` (state, detection rate, capture-to-publish latency, dropped frames,
reprojection error; ``ready`` once it has a camera model and frames). While the tag is not
seen, predictions are published for up to ``coast_timeout`` after the last measurement,
stamped with each new frame's capture time; their state stamp stays the last frame in which
the tag was seen, so nothing downstream takes a prediction for a fresh measurement. After that
nothing is published (no stale poses).

Frozen camera: a driver that hangs may repeat its last image with fresh stamps, while a real
sensor (and camera_sim, whose frames carry noise) never delivers two byte-identical frames.
No copy of the previous frame is posed; from the ``frozen_frames``-th identical frame in a row
the state is FROZEN (diagnostics ERROR "camera frozen"; no pose, odometry or tf) until a frame
differs. A frame whose stamp does not advance past the previous one is refused. The states
are :class:`frog_vision.core.tracking_state.TrackingStates`.

Kick inputs: with ``kick_topic`` set (default ``frog/bridge/sent``, the bridge's record of
every limb firing) each firing is given to the filter, which then follows the power stroke for
``kick_window`` and coasts with drag otherwise (``frog_vision.core.state_filter``).
``estimator:=frame_difference`` replaces the filter with the paper's own estimate (each frame's
raw pose, velocities as differences of consecutive frames), for replaying the authors' runs.
"""
from __future__ import annotations

import sys

import numpy as np
from geometry_msgs.msg import PoseStamped, TransformStamped
from nav_msgs.msg import Odometry
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import CameraInfo, Image
from soft_robot_common import ConfigurationError, MessageGate, NodeDiagnostics, declare_parameters, run_node
from soft_robot_interfaces.msg import LimbActivation, TrackerState

from frog_common.se2 import set_yaw
from frog_common.settings import from_params
from frog_vision.core.detection import DetectorSettings
from frog_vision.core.pose import PoseSettings
from frog_vision.core.tracker import Tracker, annotate
from frog_vision.core.tracking_state import TrackingStates
from frog_vision.nodes.common import load_camera, load_camera_pose
from frog_vision.nodes.messages import (array_to_image, image_to_array, model_from_camera_info, planar_covariance,
                                        s_to_stamp, stamp_to_s)
from frog_vision.nodes.settings import TRACKER_PARAMS as PARAMS
from frog_vision.nodes.settings import filter_problem, filter_settings


class TrackerNode(Node):
    NODE_NAME = "tracker_node"

    def __init__(self):
        super().__init__("tracker_node")
        p = declare_parameters(self, PARAMS, validate=filter_problem, on_change=self._apply)
        self.cfg = dict(p)
        self.fixed_camera = load_camera(p["camera_info_file"])
        self.camera_pose = load_camera_pose(p["tank_calibration_file"])
        if not p["tank_calibration_file"]:
            self.get_logger().warn("no tank_calibration_file: assuming the default camera pose 0.8 m over the tank")
        try:
            self.detector = from_params(DetectorSettings, p, family=p["tag_family"], tag_ids=(p["tag_id"],))
            self.pose_settings = from_params(PoseSettings, p)
            self.filter_settings = filter_settings(p)
        except ValueError as exc:
            raise ConfigurationError(str(exc)) from exc
        self.tracker: Tracker | None = None
        self.states = TrackingStates(p["frozen_frames"])
        self.gate = MessageGate(self)     # non-finite, unstamped or oversized inputs are refused
        self.last_kick: float | None = None       # stamp of the last limb firing [s]
        if self.fixed_camera is not None:
            self._make_tracker(self.fixed_camera)
        # keep the newest frame only: a busy tracker skips frames instead of working through old ones
        # (each one queued adds a frame interval to the age of every decision). Reliable: best-effort
        # loses most 0.9 MB frames on the way (a lost UDP fragment drops the whole sample), and a
        # keep-last writer never blocks on it.
        sensor = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE)
        self.create_subscription(Image, "camera/image_raw", self.on_image, sensor)
        self.create_subscription(CameraInfo, "camera/camera_info", self.on_info, QoSProfile(
            depth=2, reliability=ReliabilityPolicy.RELIABLE))
        if p["kick_topic"]:
            self.create_subscription(LimbActivation, p["kick_topic"], self.on_kick,
                                     QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
        self.pose_pub = self.create_publisher(PoseStamped, "frog/pose", 10)
        self.odom_pub = self.create_publisher(Odometry, "frog/odom", 10)
        self.state_pub = self.create_publisher(TrackerState, "frog/tracker/state", 10)
        self.debug_pub = self.create_publisher(Image, "frog/tracker/debug_image", 2)
        self.tf_pub = None
        if p["publish_tf"]:
            try:
                from tf2_msgs.msg import TFMessage
            except ImportError:
                self.get_logger().warning("tf2_msgs is not installed: not publishing tf")
            else:
                self._TFMessage = TFMessage
                self.tf_pub = self.create_publisher(TFMessage, "tf", 100)
        self.diagnostics = NodeDiagnostics(self, "tag tracking", self._diagnostics, hardware_id="camera")
        self.get_logger().info(f"tracking {p['tag_family']} id {p['tag_id']} ({p['tag_size'] * 1e3:g} mm)")

    def _apply(self, changed: dict) -> None:
        self.cfg.update(changed)
        if "frozen_frames" in changed:
            self.states.frozen.frozen_frames = int(changed["frozen_frames"])
        self.filter_settings = filter_settings(self.cfg)
        if self.tracker is not None:
            self.tracker.filter.settings = self.filter_settings

    def _make_tracker(self, camera) -> None:
        self.tracker = Tracker(camera, self.camera_pose, self.detector, self.pose_settings, self.filter_settings,
                               self.cfg["search_window"], self.cfg["estimator"])
        if self.last_kick is not None:            # a firing before the first camera_info still counts
            self.tracker.kick(self.last_kick)

    def _error(self, text: str) -> None:
        if self.states.error(text):               # a stream of the same bad frames is logged once
            self.get_logger().error(text)

    def _log(self, change) -> None:
        if change is not None:                    # rclpy wants one severity per call site
            if change.error:
                self.get_logger().error(change.text)
                return
            if change.warn:
                self.get_logger().warning(change.text)
            else:
                self.get_logger().info(change.text)
            self.diagnostics.publish()            # say it at once, not at the next 1 s tick

    # -- inputs ------------------------------------------------------------------------------
    def on_kick(self, msg: LimbActivation) -> None:
        if self.gate.refused(self.cfg["kick_topic"], msg) or not msg.limbs:     # nothing heated: no kick
            return
        stamp = stamp_to_s(msg.header.stamp)
        if not np.isfinite(stamp) or stamp <= 0:
            self._error(f"ignored limb firing with stamp {stamp!r}")
            return
        if self.last_kick is None:
            self.get_logger().info(f"kick inputs from {self.cfg['kick_topic']}: filtering with the stroke model")
        self.last_kick = stamp
        if self.tracker is not None:
            self.tracker.kick(stamp)

    def on_info(self, msg: CameraInfo) -> None:
        if self.gate.refused("camera/camera_info", msg, stamped=False) or self.fixed_camera is not None:
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
        if self.tracker is None:
            self._error("no camera_info received yet: cannot use images")
            return
        try:
            img = image_to_array(msg)
            self.tracker.camera.check_image(img)
        except ValueError as exc:
            self._error(f"refused bad frame: {exc}")
            return
        stamp = stamp_to_s(msg.header.stamp)
        verdict, change = self.states.admit(stamp, msg.data)
        if verdict == "frozen":
            self.publish_state(msg.header.stamp)
        self._log(change)
        if verdict != "use":
            return
        res = self.tracker.process(img, stamp)
        change = self.states.processed(
            stamp, seen=res.measurement is not None, publishing=res.state is not None,
            coasting=res.state is not None and res.state.coasting, reason=res.reason,
            latency_s=self.get_clock().now().nanoseconds * 1e-9 - stamp, compute_s=res.compute_s,
            residual_px=res.measurement.residual_px if res.measurement is not None else np.nan)
        self.publish_state(msg.header.stamp)
        if res.state is not None:
            self.publish_pose(msg.header.stamp, res.state)
        self._log(change)
        if self.cfg["publish_debug_image"]:
            self.debug_pub.publish(array_to_image(annotate(img, res), msg.header.stamp, msg.header.frame_id))

    # -- outputs -----------------------------------------------------------------------------
    def publish_state(self, stamp) -> None:
        """frog/tracker/state for this frame: before the pose, so a subscriber has it first."""
        msg = TrackerState(state=self.states.state)
        msg.header.stamp, msg.header.frame_id = stamp, self.cfg["world_frame"]
        if self.states.state_stamp is not None:
            msg.state_stamp = s_to_stamp(self.states.state_stamp)
        self.state_pub.publish(msg)

    def publish_pose(self, stamp, st) -> None:
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
        odom.pose.covariance = planar_covariance(st.pose_covariance)
        odom.twist.covariance = planar_covariance(st.twist_covariance)
        self.odom_pub.publish(odom)
        if self.tf_pub is not None:
            tf = TransformStamped()
            tf.header = pose.header
            tf.child_frame_id = self.cfg["body_frame"]
            tf.transform.translation.x, tf.transform.translation.y = pose.pose.position.x, pose.pose.position.y
            tf.transform.rotation = pose.pose.orientation
            self.tf_pub.publish(self._TFMessage(transforms=[tf]))

    def _diagnostics(self):
        level, message, values = self.states.report()
        values["state_age_s"] = self.states.state_age(self.get_clock().now().nanoseconds * 1e-9)
        values["ready"] = self.tracker is not None and self.states.frames > 0
        return level, message, values


def main(args=None) -> int:
    return run_node(TrackerNode, args)


if __name__ == "__main__":
    sys.exit(main())
