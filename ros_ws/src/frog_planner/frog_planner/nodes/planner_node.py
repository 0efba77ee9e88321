"""``planner_node``: library-backed receding-horizon path following (paper Algorithm 1).

Every ``period`` it decides on the newest state (``odom_topic``, nav_msgs/Odometry, paired with
the tracker's ``state_topic`` for the capture stamp of the measurement behind it) and publishes
the primitive on ``frog/primitive`` carrying that stamp (``state_stamp``), the decision and its
state on ``frog/planner/status``; the path is latched on ``frog/path``. It publishes I (no
action) and says why when stopped (``~/stop``, ``frog/stop``), at the goal, without a library,
or WAITING while the newest state is missing or older than ``max_state_age_s`` (the same
bound bridge_node enforces). Weights, depth, look-aheads, the path and ``library_file`` can be
set live. ``transitions`` simulator decides on rollouts of the DER (``frog/rollouts``) at a
deadline; ``replan_interval`` > 0 runs the authors' own asynchronous loop. The loop is
:class:`frog_planner.core.decision_loop.DecisionLoop`; this module only carries messages.
"""

from __future__ import annotations

import sys

from geometry_msgs.msg import Pose2D
from nav_msgs.msg import Odometry
from nav_msgs.msg import Path as PathMsg
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from soft_robot_common import ConfigurationError, MessageGate, NodeDiagnostics, declare_parameters, run_node
from std_msgs.msg import Empty
from std_srvs.srv import Trigger

from frog_common.motion_library_file import LibraryFormatError
from frog_common.se2 import yaw_of
from frog_common.settings import from_params
from frog_planner.core import decision_loop as dl
from frog_planner.core.feasibility import describe_tight, steady_turns, turning_limits
from frog_planner.core.planner import Planner
from frog_planner.core.settings import PathSettings, PlannerSettings
from frog_planner.core.status import loop_report, status_fields
from frog_planner.core.transition_model import TransitionModel
from frog_planner.nodes.messages import path_message, seconds, to_time
from frog_planner.nodes.planner_params import PARAMS, PATH_PARAMS, check_settings
from frog_planner.nodes.rollout_client import RolloutClient


class PlannerNode(Node):
    """See the module docstring; parameters in :mod:`frog_planner.nodes.planner_params`."""

    NODE_NAME = "planner_node"

    def __init__(self, **kwargs):
        super().__init__("planner_node", **kwargs)
        self.gate = MessageGate(self)     # non-finite, unstamped or oversized odometry is refused
        self.cfg = p = declare_parameters(self, PARAMS, validate=check_settings, on_change=self.on_parameters)
        self.settings = from_params(PlannerSettings, p)
        try:
            self.path = from_params(PathSettings, p).build()
        except (ValueError, OSError) as exc:
            raise ConfigurationError(str(exc)) from exc
        from soft_robot_interfaces.msg import LimbActivation, PlannerStatus, Primitive, TrackerState
        self._Primitive, self._Status = Primitive, PlannerStatus
        self.loop = dl.DecisionLoop(self._loop_settings(), lambda: self.get_clock().now().nanoseconds * 1e-9,
                                    paired=bool(p["state_topic"]), autostart=p["autostart"],
                                    source=f"odometry on {self.resolve_topic_name(p['odom_topic'])}")
        qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.primitive_pub = self.create_publisher(Primitive, "frog/primitive", qos)
        self.status_pub = self.create_publisher(PlannerStatus, "frog/planner/status", qos)
        self.path_pub = self.create_publisher(PathMsg, "frog/path", latched)
        self.create_subscription(Odometry, p["odom_topic"], self.on_odom, qos)
        if p["state_topic"]:
            self.create_subscription(TrackerState, p["state_topic"], self.on_tracker_state, QoSProfile(
                depth=30, reliability=ReliabilityPolicy.RELIABLE))
        self.create_service(Trigger, "~/start", self.on_start)
        self.create_service(Trigger, "~/stop", self.on_stop)
        self.create_subscription(Empty, "frog/stop", self.on_stop_topic, qos)
        self.rollouts = RolloutClient(self, p["rollout_service"], {LimbActivation.LIMB_FL: "FL",
                                      LimbActivation.LIMB_FR: "FR", LimbActivation.LIMB_BL: "BL",
                                      LimbActivation.LIMB_BR: "BR"})
        self.create_subscription(LimbActivation, p["sent_topic"], self.rollouts.on_sent, qos)
        self._future = self._deadline_timer = None      # transitions simulator: the pending request
        self.limits = None              # the frog's steady turning circles (feasibility), from the model
        self.load_library()
        if self.loop.planner is not None and p["initial_progress"] > 0:
            self.loop.planner.reset(p["initial_progress"])
        self.publish_path()
        if p["replan_interval"] > 0:
            self.create_timer(p["replan_interval"], self.replan)
        self.create_timer(self.settings.period, self.decide)
        self.diagnostics = NodeDiagnostics(self, "planner", self._diagnostics, hardware_id="planner")
        self.get_logger().info(
            f"following a {self.path.name} path of {self.path.length:.3f} m, period {self.settings.period} s, "
            f"depth {self.settings.depth}, transitions {p['transitions']}, states at most {p['max_state_age_s']:g} "
            f"s old; {self.loop.source}; " + (f"not planning: {self.loop.library_error}" if self.loop.library_error
                                               else 'running' if self.loop.running else 'waiting for ~/start'))

    def _loop_settings(self) -> dl.LoopSettings:
        return dl.LoopSettings.from_params(self.cfg, self.settings.period)

    def load_library(self) -> None:
        """Load the model; on failure log the reason and keep running (publishing I)."""
        file = self.cfg["library_file"]
        try:
            if not file:
                raise ValueError("no library_file parameter given")
            model = TransitionModel.load(file, **self.settings.model_kwargs())
            self.loop.set_planner(Planner(model, self.path, self.settings))
        except (LibraryFormatError, ValueError, OSError) as exc:
            self.limits = None
            self.loop.set_planner(None, f"cannot use library {file!r}: {exc} (set library_file to fix it: ros2 "
                                        f"param set <node> library_file <file>)")
            self.get_logger().error(self.loop.library_error + "; publishing primitive I until fixed")
            return
        self.limits = turning_limits(steady_turns(model, self.settings.period))
        self.get_logger().info(f"library {file}: {model.n_states} states, {model.n_primitives} primitives; "
                               f"{self.limits.describe()}")
        self.get_logger().info(describe_tight(self.path, self.limits))

    def on_parameters(self, changed: dict) -> None:
        """Apply live changes: planner settings keep the progress, a new path starts over."""
        self.settings = from_params(PlannerSettings, self.cfg)
        self.loop.settings = self._loop_settings()
        old = self.loop.planner
        progress = old.progress if old is not None else 0.0
        if changed.keys() & {r.name for r in PATH_PARAMS}:
            try:
                self.path = from_params(PathSettings, self.cfg).build()
            except (ValueError, OSError) as exc:
                self.get_logger().error(f"new path not usable ({exc}); keeping the {self.path.name} path")
                return
            self.loop.goal_reached, progress = False, 0.0
            self.publish_path()
        if "library_file" in changed:
            self.load_library()
        elif old is not None:
            self.loop.set_planner(Planner(old.model, self.path, self.settings))
            if changed.keys() & {r.name for r in PATH_PARAMS} and self.limits is not None:
                self.get_logger().info(describe_tight(self.path, self.limits))
        if self.loop.planner is not None:
            self.loop.planner.reset(progress)

    def publish_path(self) -> None:
        msg = path_message(self.path, self.cfg["world_frame"], self.get_clock().now().to_msg())
        self.path_pub.publish(msg)
        # under use_sim_time the clock reads 0 until /clock arrives: publish again once it runs
        self._path_unstamped = msg.header.stamp.sec == 0 and msg.header.stamp.nanosec == 0

    # -- inputs ------------------------------------------------------------------------------
    def on_odom(self, msg: Odometry) -> None:
        p, q, tw = msg.pose.pose.position, msg.pose.pose.orientation, msg.twist.twist
        problem = self.gate.problem(msg)                 # every float finite, stamped (one rule)
        if not problem and abs(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w - 1.0) > 1e-3:
            problem = "its orientation is not a unit quaternion"
        if problem:
            if self.gate.should_log("odometry", problem):  # once a second per field and value
                self.get_logger().error(f"ignored odometry: {problem}")
            return
        self.loop.odometry((p.x, p.y, yaw_of(q)), (tw.linear.x, tw.linear.y, tw.angular.z), seconds(msg.header.stamp))

    def on_tracker_state(self, msg) -> None:
        if not self.gate.refused(self.cfg["state_topic"], msg):
            state = seconds(msg.state_stamp)
            self.loop.tracker_state(seconds(msg.header.stamp), state if state > 0 else None)

    def on_start(self, request, response):
        reason = self.loop.start()
        if reason:
            self.get_logger().error(f"~/start refused: {reason}")
        response.success = reason is None
        response.message = f"cannot follow the path: {reason}" if reason else f"following the {self.path.name} path"
        return response

    def on_stop(self, request, response):
        self.loop.stop()
        response.success, response.message = True, "stopped; publishing primitive I"
        return response

    def on_stop_topic(self, msg) -> None:
        if self.loop.running:
            self.get_logger().warn(f"stop received on {self.resolve_topic_name('frog/stop')}")
        self.loop.stop()

    # -- decisions -----------------------------------------------------------------------------
    def decide(self) -> None:
        if self._path_unstamped:
            self.publish_path()
        if self.loop.pending is not None:            # a deadline the clock skipped past: close it first
            self.finish_deadline()
        out = self.loop.tick()
        if isinstance(out, dl.RolloutRequest):
            s = out.sample
            self._future, self._reason = self.rollouts.request(
                s.pose, s.twist, to_time(s.stamp, self.get_clock()), self.settings.period, out.depth, out.lead,
                out.first_primitives)
            self._deadline_timer = self.create_timer(out.deadline - self.loop.clock(), self.finish_deadline)
        else:
            self.publish(out)

    def finish_deadline(self) -> None:
        if self._deadline_timer is not None:
            self.destroy_timer(self._deadline_timer)
            self._deadline_timer = None
        planner = self.loop.planner
        expander, reason = self.rollouts.result(self._future, self._reason, planner.model.primitive_names,
                                                planner.depth, self.cfg["reanchor"], self.cfg["decision_deadline"],
                                                self.settings.period)
        out = self.loop.finish(expander, reason)
        if out is not None:
            self.publish(out)

    def replan(self) -> None:
        if problem := self.loop.replan():
            self.get_logger().error(problem, throttle_duration_sec=2.0)

    def publish(self, out: dl.Outcome) -> None:
        for severity, text in out.logs:          # rclpy wants one severity per call site
            if severity == "error":
                self.get_logger().error(text)
            elif severity == "warn":
                self.get_logger().warning(text)
            else:
                self.get_logger().info(text)
        pid, name = out.primitive
        msg = self._Primitive(id=pid, name=name)
        msg.header.stamp, msg.header.frame_id = self.get_clock().now().to_msg(), self.cfg["world_frame"]
        if out.state_stamp is not None and pid != self._Primitive.ID_I:
            msg.state_stamp = to_time(out.state_stamp, self.get_clock()).to_msg()
        self.primitive_pub.publish(msg)
        fields = status_fields(out, self.loop, self.settings.weights, self.path, self.limits,
                               self.cfg["feasibility_lookahead"])
        x, y, th = fields.pop("predicted_pose")
        self.status_pub.publish(self._Status(header=msg.header, predicted_pose=Pose2D(x=x, y=y, theta=th), **fields))

    def _diagnostics(self):
        level, message, values = loop_report(self.loop, self.path.name)
        return level, message, {"library_file": self.cfg["library_file"], **values,
                                "last_rollout_s": self.rollouts.last_compute_s}

    def destroy_node(self):
        if self.loop.simulator_decisions or self.loop.fallback_decisions:     # the run's count, for reports
            self.get_logger().info(f"decisions: {self.loop.simulator_decisions} simulator, "
                                   f"{self.loop.fallback_decisions} library fallbacks")
        return super().destroy_node()


def main(args=None) -> int:
    return run_node(PlannerNode, args)


if __name__ == "__main__":
    sys.exit(main())
