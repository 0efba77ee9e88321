"""``planner_node``: library-backed receding-horizon path following (paper Algorithm 1).

Every ``period`` seconds it takes the latest odometry (``odom_topic``, nav_msgs/Odometry:
pose in the world frame, twist in the body frame per REP-105), asks
:class:`frog_planner.core.planner.Planner` for the best primitive, and publishes it on
``/frog/primitive`` with the decision on ``/frog/planner/status``. The reference path is
latched on ``/frog/path``. It publishes primitive I (no action) and logs why when it is
stopped (``~/stop``), when the goal is reached, when odometry is missing or older than
``stale_periods`` periods, or when the library cannot be used.
"""

from __future__ import annotations

import math
import sys

from geometry_msgs.msg import Pose2D, PoseStamped
from nav_msgs.msg import Odometry
from nav_msgs.msg import Path as PathMsg
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from soft_robot_common import ConfigurationError, declare_parameters, run_node
from std_srvs.srv import Trigger

from frog_planner.core.library_file import LibraryFormatError
from frog_planner.core.paths import ellipse_path, line_path, sinusoid_path, waypoint_path_from_csv
from frog_planner.core.planner import Planner
from frog_planner.core.transition_model import TransitionModel
from frog_planner.core.tree_search import CostWeights

_PARAMS = [
    ("library_file", "", "motion-primitive library (.npz, docs/motion_library_format.md)"),
    ("period", 1.5, "primitive period T [s] (a multiple of the library's sample interval)"),
    ("depth", 1, "tree search depth H (1-5; the paper found 1 best on hardware)"),
    ("metric", "euclidean", "nearest-neighbour metric: euclidean (scaled, KD-tree) or relative"),
    ("k_neighbours", 1, "nearest library states averaged"),
    ("gradient_correction", True, "correct the nearest state's transitions to first order for the "
                                   "velocity difference (library-fitted slopes); false = the paper"),
    ("w_distance", 500.0, "eq. 19 weight w_a of the distance to the path"),
    ("w_heading", 50.0, "eq. 19 weight w_b of the heading error"),
    ("w_progress", 300.0, "eq. 19 weight w_c of (1 - progress)"),
    ("heading_lookahead", 0.1, "heading error against the path this far ahead [m]; 0 = the "
                               "paper's path tangent at the closest point"),
    ("velocity_lookahead", 1.5, "cost each leaf pose extrapolated by its predicted body velocities "
                                "and yaw rate over this time [s]; 0 = the paper (cost at the leaf)"),
    ("stall_speed", 0.002, "below this planar speed [m/s] (and 0.01 rad/s yaw rate) short of the goal, "
                           "never choose 'no action' (it would wait forever); 0 = the paper"),
    ("path_type", "line", "line, sine, ellipse or waypoints"),
    ("path_length", 0.0, "path length/size [m]; 0 = the paper's value for the path type"),
    ("path_start_x", 0.0, "path start x in the world frame [m]"),
    ("path_start_y", 0.0, "path start y in the world frame [m]"),
    ("path_heading", 0.0, "direction of the path at its start [rad]"),
    ("waypoint_file", "", "CSV with header x,y [m] (path_type waypoints)"),
    ("goal_tolerance", 0.03, "distance to the path's end that counts as reached [m]"),
    ("goal_lateral_tolerance", 0.0, "crossing the finish line (normal at the path's end) counts only "
                                    "this close to the end along that line [m]; 0 = goal_tolerance"),
    ("odom_topic", "/frog/odom", "odometry input (tracker, or the simulator's ground truth)"),
    ("world_frame", "tank", "frame of the path and the status poses"),
    ("stale_periods", 2.0, "odometry older than this many periods is stale"),
    ("autostart", True, "start following at once (else wait for ~/start)"),
]


def yaw_of(q) -> float:
    """Yaw [rad] of a geometry_msgs quaternion (rotation about z)."""
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def build_path(p: dict):
    """The reference path from the node parameters (core path builders)."""
    goal = {"goal_tolerance": p["goal_tolerance"],
            "goal_lateral_tolerance": p["goal_lateral_tolerance"] or None}
    kw = {"start": (p["path_start_x"], p["path_start_y"]), "heading": p["path_heading"], **goal}
    if p["path_length"] > 0:
        kw["length"] = p["path_length"]
    kind = p["path_type"]
    if kind == "line":
        return line_path(**kw)
    if kind == "sine":
        return sinusoid_path(**kw)
    if kind == "ellipse":
        return ellipse_path(**kw)
    if kind == "waypoints":
        if not p["waypoint_file"]:
            raise ConfigurationError("path_type waypoints needs the parameter waypoint_file")
        return waypoint_path_from_csv(p["waypoint_file"], **goal)
    raise ConfigurationError(f"path_type {kind!r} is not one of line, sine, ellipse, waypoints")


class PlannerNode(Node):
    """See the module docstring; parameters in ``_PARAMS``."""

    NODE_NAME = "planner_node"

    def __init__(self, **kwargs):
        super().__init__("planner_node", **kwargs)
        p = declare_parameters(self, _PARAMS)
        self.cfg = p
        self._validate(p)
        try:
            self.path = build_path(p)
            self.weights = CostWeights(p["w_distance"], p["w_heading"], p["w_progress"])
        except (ValueError, OSError) as exc:
            raise ConfigurationError(str(exc)) from exc
        from soft_robot_interfaces.msg import PlannerStatus, Primitive
        self._Primitive, self._Status = Primitive, PlannerStatus
        qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.primitive_pub = self.create_publisher(Primitive, "/frog/primitive", qos)
        self.status_pub = self.create_publisher(PlannerStatus, "/frog/planner/status", qos)
        self.path_pub = self.create_publisher(PathMsg, "/frog/path", latched)
        self.create_subscription(Odometry, p["odom_topic"], self.on_odom, qos)
        self.create_service(Trigger, "~/start", self.on_start)
        self.create_service(Trigger, "~/stop", self.on_stop)
        self.planner = None
        self.library_error = None
        self.load_library()
        self.running = bool(p["autostart"])
        self.odom = None
        self.odom_received = None
        self.goal_reached = False
        self._last_reason = None
        self.publish_path()
        self.create_timer(p["period"], self.decide)
        self.get_logger().info(
            f"following a {self.path.name} path of {self.path.length:.3f} m, period {p['period']} s, "
            f"depth {p['depth']}, metric {p['metric']}; odometry from {p['odom_topic']}; "
            f"{'running' if self.running else 'waiting for ~/start'}")

    @staticmethod
    def _validate(p: dict) -> None:
        checks = [("period", p["period"] > 0, "> 0 s"), ("depth", 1 <= p["depth"] <= 5, "in 1-5"),
                  ("metric", p["metric"] in ("euclidean", "relative"), "euclidean or relative"),
                  ("k_neighbours", p["k_neighbours"] >= 1, ">= 1"),
                  ("stale_periods", p["stale_periods"] > 0, "> 0"),
                  ("goal_tolerance", p["goal_tolerance"] > 0, "> 0 m"),
                  ("path_length", p["path_length"] >= 0, ">= 0 m"),
                  ("goal_lateral_tolerance", p["goal_lateral_tolerance"] >= 0, ">= 0 m"),
                  ("heading_lookahead", p["heading_lookahead"] >= 0, ">= 0 m"),
                  ("velocity_lookahead", p["velocity_lookahead"] >= 0, ">= 0 s"),
                  ("stall_speed", p["stall_speed"] >= 0, ">= 0 m/s")]
        for name, ok, expected in checks:
            if not ok:
                raise ConfigurationError(f"parameter {name} = {p[name]!r} must be {expected}")
        for name in ("w_distance", "w_heading", "w_progress", "path_start_x", "path_start_y",
                     "path_heading", "period", "path_length", "heading_lookahead", "velocity_lookahead", "stall_speed",
                     "goal_tolerance", "goal_lateral_tolerance"):
            if not math.isfinite(p[name]):
                raise ConfigurationError(f"parameter {name} = {p[name]!r} must be finite")

    def load_library(self) -> None:
        """Load the model; on failure log the reason and keep running (publishing I)."""
        p = self.cfg
        if not p["library_file"]:
            self.library_error = "no library_file parameter given"
        else:
            try:
                model = TransitionModel.load(p["library_file"], period=p["period"],
                                             metric=p["metric"], k=p["k_neighbours"],
                                             gradient_correction=p["gradient_correction"])
                self.planner = Planner(model, self.path, self.weights, p["depth"],
                                       heading_lookahead=p["heading_lookahead"],
                                       velocity_lookahead=p["velocity_lookahead"],
                                       stall_speed=p["stall_speed"])
                self.library_error = None
                self.get_logger().info(f"library {p['library_file']}: {model.n_states} states, "
                                       f"{model.n_primitives} primitives")
                return
            except (LibraryFormatError, ValueError, OSError) as exc:
                self.library_error = f"cannot use library {p['library_file']!r}: {exc}"
        self.get_logger().error(self.library_error + "; publishing primitive I until fixed")

    def publish_path(self) -> None:
        msg = PathMsg()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = self.cfg["world_frame"]
        for (x, y), h in zip(self.path.points, self.path.tangent_headings):
            ps = PoseStamped()
            ps.header = msg.header
            ps.pose.position.x, ps.pose.position.y = float(x), float(y)
            ps.pose.orientation.z, ps.pose.orientation.w = math.sin(h / 2), math.cos(h / 2)
            msg.poses.append(ps)
        self.path_pub.publish(msg)

    # -- inputs ------------------------------------------------------------------------------
    def on_odom(self, msg: Odometry) -> None:
        p, q, tw = msg.pose.pose.position, msg.pose.pose.orientation, msg.twist.twist
        values = (p.x, p.y, q.x, q.y, q.z, q.w, tw.linear.x, tw.linear.y, tw.angular.z)
        if not all(math.isfinite(v) for v in values):
            self.get_logger().error("ignored odometry with non-finite values",
                                    throttle_duration_sec=2.0)
            return
        if abs(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w - 1.0) > 1e-3:
            self.get_logger().error("ignored odometry with a non-unit quaternion",
                                    throttle_duration_sec=2.0)
            return
        self.odom = ((p.x, p.y, yaw_of(q)), (tw.linear.x, tw.linear.y, tw.angular.z))
        self.odom_received = self.get_clock().now()

    def on_start(self, request, response):
        if self.goal_reached:
            self.planner.reset()
            self.goal_reached = False
        self.running = True
        response.success, response.message = True, "following the path"
        self.get_logger().info("started")
        return response

    def on_stop(self, request, response):
        self.running = False
        response.success, response.message = True, "stopped; publishing primitive I"
        self.get_logger().info("stopped by ~/stop")
        return response

    # -- decisions -----------------------------------------------------------------------------
    def _idle_reason(self):
        if self.library_error:
            return self.library_error
        if not self.running:
            return "stopped"
        if self.goal_reached:
            return "goal reached"
        if self.odom is None:
            return f"no odometry on {self.cfg['odom_topic']} yet"
        age = (self.get_clock().now() - self.odom_received).nanoseconds * 1e-9
        if age > self.cfg["stale_periods"] * self.cfg["period"]:
            return f"odometry is stale ({age:.2f} s old)"
        return None

    def _publish(self, primitive_id: int, name: str, decision=None) -> None:
        stamp = self.get_clock().now().to_msg()
        msg = self._Primitive(id=primitive_id, name=name)
        msg.header.stamp = stamp
        msg.header.frame_id = self.cfg["world_frame"]
        self.primitive_pub.publish(msg)
        status = self._Status(primitive_id=primitive_id, primitive_name=name)
        status.header.stamp, status.header.frame_id = stamp, self.cfg["world_frame"]
        if decision is not None:
            w = self.weights
            t = decision.cost_terms
            status.total_cost = float(decision.total_cost)
            status.cost_distance = t.distance / w.distance if w.distance else 0.0
            status.cost_heading = t.heading / w.heading if w.heading else 0.0
            status.cost_progress = t.progress / w.progress if w.progress else 0.0
            x, y, th = (float(v) for v in decision.predicted_pose)
            status.predicted_pose = Pose2D(x=x, y=y, theta=th)
            status.path_progress = float(decision.progress)
            status.distance_to_path = float(decision.distance_to_path)
        elif self.planner is not None:
            status.path_progress = float(self.planner.progress)
        self.status_pub.publish(status)

    def decide(self) -> None:
        reason = self._idle_reason()
        if reason is None:
            pose, velocity = self.odom
            try:
                d = self.planner.decide(pose, velocity)
            except ValueError as exc:
                reason = f"planner rejected the state: {exc}"
            else:
                if d.goal_reached:
                    self.goal_reached = True
                    self.get_logger().info(
                        f"goal reached (progress {d.progress:.3f}, {d.distance_to_path * 100:.2f} cm "
                        f"from the path); publishing primitive I")
                    self._publish(8, "I", d)
                    return
                self._last_reason = None
                self._publish(d.primitive_id, d.name, d)
                return
        if reason != self._last_reason:
            self.get_logger().warning(f"publishing primitive I: {reason}")
            self._last_reason = reason
        self._publish(8, "I")


def main(args=None) -> int:
    return run_node(PlannerNode, args)


if __name__ == "__main__":
    sys.exit(main())
