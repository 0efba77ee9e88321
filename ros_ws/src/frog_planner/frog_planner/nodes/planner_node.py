"""``planner_node``: library-backed receding-horizon path following (paper Algorithm 1).

Every ``period`` seconds it takes the latest odometry (``odom_topic``, nav_msgs/Odometry:
pose in the world frame, twist in the body frame per REP-105), asks
:class:`frog_planner.core.planner.Planner` for the best primitive, and publishes it on
``frog/primitive`` with the decision and the planner's state on ``frog/planner/status``
(relative names: ``__ns`` moves them). The reference path is latched on ``frog/path``. It
publishes primitive I (no action), says why in the status and logs it when the state
changes: stopped (``~/stop``, or ``frog/stop``, std_msgs/Empty, the run's one stop that
also reaches the bridge), goal reached, odometry missing or stale, or a library that cannot
be used. Odometry is stale when it was received, or is stamped (``header.stamp``: a tracker
republishing old poses, a delayed message), more than ``stale_periods`` periods ago; a stamp
that far in the future (another clock) is refused too. Each status carries ``pose_age``, the
age of the newest pose by its stamp (NaN before the first), and the diagnostics count the
decisions refused for a stale or missing pose (``stale_decisions``). Weights, depth, look-aheads,
the path and ``library_file`` can be changed while running (``ros2 param set``); setting
``library_file`` (to a new path, or again to the same one after fixing the file) loads it
anew, so a missing or corrupt library is fixed without a restart.

``transitions`` (live) chooses the predictions the search chains: ``library`` (the paper's
nearest library state) or ``simulator`` (the paper's future work): at each tick the node
asks ``frog/rollouts`` (frog_sim ``rollout_node``) for the tree from the tracked pose and
twist and the limbs' firing ages (``frog/bridge/sent``), coasted to the moment the decision
is executed, ``decision_deadline`` periods after the tick. The decision is published then.
A response that has not arrived by then, a refusal or a missing service makes that one
decision a library decision on the newest pose, with a WARN and a count in diagnostics
(``fallback_decisions``). Depth 2 expands all 81 sequences, or with ``beam_width`` k only
the k first primitives the library ranks best.

``replan_interval`` > 0 runs the paper's own loop instead (its published control code, for
replaying the authors' experiments): every ``replan_interval`` seconds a library decision is
made on the mean of the odometry received since the previous one
(:mod:`frog_planner.core.state_window`), and each period tick publishes the newest of them, each
once (none new: primitive I). A
decision then acts on a state some 0.3-1 s old, as on the authors' robot; 0 (the default)
decides at the tick on the newest pose.
"""

from __future__ import annotations

import math
import re
import sys

from geometry_msgs.msg import Pose2D, PoseStamped
from nav_msgs.msg import Odometry
from nav_msgs.msg import Path as PathMsg
from rclpy.node import Node
from rclpy.time import Time
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from soft_robot_common import (ConfigurationError, MessageGate, NodeDiagnostics, Param, declare_parameters,
                               params_from_dataclass, run_node)
from soft_robot_common.diagnostics import ERROR, OK, WARN
from std_msgs.msg import Empty
from std_srvs.srv import Trigger

from frog_planner.core.feasibility import radius_ahead, steady_turns, tight_stretches, turning_limits
from frog_common.motion_library_file import LibraryFormatError
from frog_planner.core.planner import Planner
from frog_planner.core.settings import PathSettings, PlannerSettings
from frog_common.settings import from_params
from frog_planner.core.state_window import StateWindow
from frog_planner.core.transition_model import TransitionModel
from frog_planner.nodes.rollout_client import RolloutClient, lead_time
from frog_common.primitives import NO_ACTION
from frog_common.se2 import set_yaw, yaw_of

TRANSITIONS = ("library", "simulator")
SIMULATOR_MAX_DEPTH = 2

# The node's own settings; the planner's and the path's come from frog_planner.core.settings.
_NODE_PARAMS = [
    Param("library_file", "", "motion-primitive library (.npz, docs/motion_library_format.md); live: set it "
          "(again) to load a new or fixed file", live=True),
    Param("odom_topic", "frog/odom", "odometry input (tracker, or the simulator's ground truth); relative "
          "names resolve in the node's namespace"),
    Param("world_frame", "tank", "frame of the path and the status poses"),
    Param("stale_periods", 2.0, "odometry received, or stamped, longer ago than this many periods is stale: "
          "primitive I until a fresh one arrives", min=0.1, max=100.0, live=True),
    Param("autostart", True, "start following at once (else wait for ~/start)"),
    Param("feasibility_lookahead", 0.1, "the status compares the path's tightest bend this far ahead with the "
          "frog's tightest steady turn (path_too_tight)", min=0.0, max=10.0, live=True),
    Param("transitions", "library", "predictions the search chains: library (the paper) or simulator "
          "(rollouts of the DER from the estimated state, frog/rollouts; depth 1-2)", choices=TRANSITIONS,
          live=True),
    Param("rollout_service", "frog/rollouts", "the simulator's rollout service (transitions simulator)"),
    Param("sent_topic", "frog/bridge/sent", "what the bridge fired (LimbActivation): the limbs' firing ages in "
          "the rollouts' start state"),
    Param("decision_deadline", 0.7, "transitions simulator: the decision is executed this many periods after "
          "the tick (the rollouts start from the state predicted then); a later response falls back to the "
          "library for that decision", min=0.05, max=0.95, live=True),
    Param("reanchor", True, "transitions simulator: decide at the deadline on the newest tracked pose, the rollouts' "
          "tree chained from it (their prediction of the lead replaced by the tracking); false: on the tick's pose "
          "and the rollouts' prediction of the lead", live=True),
    Param("beam_width", 0, "transitions simulator, depth 2: roll out only the first primitives the library "
          "ranks best, this many; 0 = all 9", min=0, max=9, live=True),
    Param("replan_interval", 0.0, "> 0: the paper's asynchronous loop: decide this often [s] on the mean of the "
          "odometry since the last decision, and publish the newest decision at each period tick (the authors "
          "averaged 9 tracker states, about 0.63 s); 0 = decide at the tick on the newest pose (transitions "
          "library only)", min=0.0, max=10.0),
    Param("initial_progress", 0.0, "progress along the path to start from, in [0, 1] (a restarted planner "
          "resumes where it was)", min=0.0, max=1.0),
]
_PLANNER_PARAMS = params_from_dataclass(PlannerSettings)
_PATH_PARAMS = params_from_dataclass(PathSettings)


def _check_settings(values: dict) -> str | None:
    """Cross-checks of a candidate parameter set (ranges are checked per parameter)."""
    try:
        from_params(PathSettings, values)
        from_params(PlannerSettings, values)
    except ValueError as exc:
        return str(exc)
    if values.get("transitions") == "simulator" and values.get("replan_interval", 0.0) > 0:
        return "replan_interval (the paper's asynchronous loop) goes with transitions library only"
    if values.get("transitions") == "simulator" and values.get("depth", 1) > SIMULATOR_MAX_DEPTH:
        return (f"transitions simulator rolls out depth 1-{SIMULATOR_MAX_DEPTH}; depth is {values['depth']} "
                f"(lower depth, or use transitions library)")
    return None


class PlannerNode(Node):
    """See the module docstring; parameters from ``_NODE_PARAMS``, PlannerSettings and PathSettings."""

    NODE_NAME = "planner_node"

    def __init__(self, **kwargs):
        super().__init__("planner_node", **kwargs)
        self.gate = MessageGate(self)     # non-finite, unstamped or oversized odometry is refused
        self.cfg = declare_parameters(self, _NODE_PARAMS + _PLANNER_PARAMS + _PATH_PARAMS,
                                      validate=_check_settings, on_change=self.on_parameters)
        p = self.cfg
        self.settings = from_params(PlannerSettings, p)
        self.path_settings = from_params(PathSettings, p)
        try:
            self.path = self.path_settings.build()
        except (ValueError, OSError) as exc:
            raise ConfigurationError(str(exc)) from exc
        from soft_robot_interfaces.msg import PlannerStatus, Primitive
        self._Primitive, self._Status = Primitive, PlannerStatus
        qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.primitive_pub = self.create_publisher(Primitive, "frog/primitive", qos)
        self.status_pub = self.create_publisher(PlannerStatus, "frog/planner/status", qos)
        self.path_pub = self.create_publisher(PathMsg, "frog/path", latched)
        self.create_subscription(Odometry, p["odom_topic"], self.on_odom, qos)
        self.create_service(Trigger, "~/start", self.on_start)
        self.create_service(Trigger, "~/stop", self.on_stop)
        self.create_subscription(Empty, "frog/stop", self.on_stop_topic, qos)
        from soft_robot_interfaces.msg import LimbActivation
        names = {LimbActivation.LIMB_FL: "FL", LimbActivation.LIMB_FR: "FR", LimbActivation.LIMB_BL: "BL",
                 LimbActivation.LIMB_BR: "BR"}
        self.rollouts = RolloutClient(self, p["rollout_service"], names)
        self.create_subscription(LimbActivation, p["sent_topic"], self.rollouts.on_sent, qos)
        self.pending = None             # the simulator decision waiting for its deadline
        self._deadline_timer = None
        self.simulator_decisions = 0
        self.fallback_decisions = 0     # simulator decisions made by the library instead
        self.last_rollout_s = math.nan  # the rollout server's compute time of the last response
        self._last_fallback = None
        self.model = None
        self.planner = None
        self.limits = None              # the frog's steady turning circles (feasibility), from the model
        self.library_error = None
        self.load_library()
        if self.planner is not None and p["initial_progress"] > 0:
            self.planner.reset(p["initial_progress"])
        self.running = bool(p["autostart"])
        self.odom = None
        self.odom_received = None       # node-clock time the newest odometry arrived
        self.odom_stamp = None          # its header stamp (rclpy Time, the node's clock type)
        self.stale_decisions = 0        # decisions refused (primitive I) for a stale or missing pose
        self.goal_reached = False
        self._last_state = None
        self.publish_path()
        self.window = StateWindow()     # replan_interval > 0: the odometry since the last decision
        self.queued = None              # ... and the newest decision (decision, its newest pose's stamp)
        if p["replan_interval"] > 0:
            self.create_timer(p["replan_interval"], self.replan)
        self.create_timer(self.settings.period, self.decide)
        self.diagnostics = NodeDiagnostics(self, "planner", self._diagnostics, hardware_id="planner")
        self.get_logger().info(
            f"following a {self.path.name} path of {self.path.length:.3f} m, period {self.settings.period} s, "
            f"depth {self.settings.depth}, metric {self.settings.metric}, transitions {p['transitions']}; "
            f"odometry from "
            f"{self.resolve_topic_name(p['odom_topic'])}; "
            + (f"not planning: {self.library_error}" if self.library_error
               else 'running' if self.running else 'waiting for ~/start'))

    def load_library(self) -> None:
        """Load the model; on failure log the reason and keep running (publishing I)."""
        p = self.cfg
        if not p["library_file"]:
            self.library_error = "no library_file parameter given"
        else:
            try:
                self.model = TransitionModel.load(p["library_file"], **self.settings.model_kwargs())
                self.planner = Planner(self.model, self.path, self.settings)
                self.library_error = None
                self.limits = turning_limits(steady_turns(self.model, self.settings.period))
                self.get_logger().info(f"library {p['library_file']}: {self.model.n_states} states, "
                                       f"{self.model.n_primitives} primitives; {self.limits.describe()}")
                self.log_feasibility()
                return
            except (LibraryFormatError, ValueError, OSError) as exc:
                self.library_error = f"cannot use library {p['library_file']!r}: {exc}"
        self.library_error += " (set library_file to fix it: ros2 param set <node> library_file <file>)"
        self.get_logger().error(self.library_error + "; publishing primitive I until fixed")

    def log_feasibility(self) -> None:
        """Say once per path and library where the path bends tighter than the frog can turn."""
        tight = tight_stretches(self.path, self.limits)
        if not tight:
            self.get_logger().info(f"the {self.path.name} path is within the frog's turning circle everywhere")
            return
        share = sum(t["end_m"] - t["start_m"] for t in tight) / self.path.length
        where = ", ".join(f"{t['start']:.2f}-{t['end']:.2f} (r {t['min_radius_m'] * 100:.1f} cm)" for t in tight)
        self.get_logger().warning(f"the {self.path.name} path bends tighter than the frog can turn over "
                                  f"{share * 100:.0f} % of its length, at progress {where}: it will cut there")

    def feasibility(self, progress: float):
        """(turn_radius_limit, path_radius_ahead, too_tight) at ``progress`` along the path."""
        if self.limits is None:
            return math.nan, math.nan, False
        r, side = radius_ahead(self.path, progress, self.cfg["feasibility_lookahead"])
        if side == 0:
            return min(self.limits.left_m, self.limits.right_m), r, False
        limit = self.limits.radius(side)
        return limit, r, r < limit

    def on_parameters(self, changed: dict) -> None:
        """Apply live changes: planner settings keep the progress, a new path starts over."""
        p = self.cfg
        self.settings = from_params(PlannerSettings, p)
        if "library_file" in changed:
            progress = self.planner.progress if self.planner is not None else 0.0
            self.model = self.planner = self.limits = None
            self.load_library()
            if self.planner is not None:
                self.planner.reset(progress)
            return
        if changed.keys() & {r.name for r in _PATH_PARAMS}:
            try:
                self.path = from_params(PathSettings, p).build()
            except (ValueError, OSError) as exc:
                self.get_logger().error(f"new path not usable ({exc}); keeping the {self.path.name} path")
                return
            self.path_settings = from_params(PathSettings, p)
            self.goal_reached = False
            self.publish_path()
            if self.limits is not None:
                self.log_feasibility()
            progress = 0.0
        else:
            progress = self.planner.progress if self.planner is not None else 0.0
        if self.model is not None:
            self.planner = Planner(self.model, self.path, self.settings)
            self.planner.reset(progress)

    def publish_path(self) -> None:
        msg = PathMsg()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = self.cfg["world_frame"]
        for (x, y), h in zip(self.path.points, self.path.tangent_headings):
            ps = PoseStamped()
            ps.header = msg.header
            ps.pose.position.x, ps.pose.position.y = float(x), float(y)
            set_yaw(ps.pose.orientation, float(h))
            msg.poses.append(ps)
        self.path_pub.publish(msg)
        # under use_sim_time the clock reads 0 until /clock arrives: publish again once it runs
        self._path_unstamped = msg.header.stamp.sec == 0 and msg.header.stamp.nanosec == 0

    # -- inputs ------------------------------------------------------------------------------
    def on_odom(self, msg: Odometry) -> None:
        p, q, tw = msg.pose.pose.position, msg.pose.pose.orientation, msg.twist.twist
        problem = self.gate.problem(msg)                 # every float finite, stamped (one rule)
        if problem:
            if self.gate.should_log("odometry", problem):  # once a second per field and value
                self.get_logger().error(("ignored odometry with non-finite values: " if "not finite" in problem
                                         else "ignored odometry: ") + problem)
            return
        if abs(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w - 1.0) > 1e-3:
            self.get_logger().error("ignored odometry with a non-unit quaternion",
                                    throttle_duration_sec=2.0)
            return
        self.odom = ((p.x, p.y, yaw_of(q)), (tw.linear.x, tw.linear.y, tw.angular.z))
        self.window.add(*self.odom)
        self.odom_received = self.get_clock().now()
        self.odom_stamp = Time.from_msg(msg.header.stamp, clock_type=self.odom_received.clock_type)

    def on_start(self, request, response):
        if self.library_error:
            response.success, response.message = False, f"cannot follow the path: {self.library_error}"
            self.get_logger().error(f"~/start refused: {self.library_error}")
            return response
        if self.goal_reached:
            self.planner.reset()
            self.goal_reached = False
        self.window.clear()
        self.queued = None
        self.running = True
        response.success, response.message = True, f"following the {self.path.name} path"
        return response

    def on_stop(self, request, response):
        self.running = False
        response.success, response.message = True, "stopped; publishing primitive I"
        return response

    def on_stop_topic(self, msg) -> None:
        if self.running:
            self.get_logger().warn(f"stop received on {self.resolve_topic_name('frog/stop')}")
        self.running = False

    # -- decisions -----------------------------------------------------------------------------
    def _state(self, now=None):
        """(state, reason) when no decision can be made at ``now`` (default: the clock's now), else None."""
        S = self._Status
        now = self.get_clock().now() if now is None else now
        if self.library_error:
            return S.STATE_ERROR, self.library_error
        if not self.running:
            return S.STATE_IDLE, "stopped (call ~/start)"
        if self.goal_reached:
            return S.STATE_GOAL_REACHED, "goal reached"
        if self.odom is None:
            return S.STATE_WAITING, f"no odometry on {self.resolve_topic_name(self.cfg['odom_topic'])} yet"
        bound = self.cfg["stale_periods"] * self.settings.period
        age = (now - self.odom_received).nanoseconds * 1e-9
        if age > bound:
            return S.STATE_WAITING, f"odometry is stale ({age:.2f} s old)"
        stamp_age = self.pose_age(now)
        if stamp_age > bound:
            return S.STATE_WAITING, (f"odometry is stale: its stamp is {stamp_age:.2f} s old (received "
                                     f"{age:.2f} s ago; bound {bound:.2f} s)")
        if stamp_age < -bound:
            return S.STATE_WAITING, (f"odometry is stamped {-stamp_age:.2f} s in the future (do the tracker "
                                     f"and the planner use the same clock? use_sim_time)")
        return None

    def pose_age(self, now=None) -> float:
        """Age of the newest pose by its header stamp, now - stamp [s]; NaN before the first."""
        if self.odom_stamp is None:
            return math.nan
        now = self.get_clock().now() if now is None else now
        return (now - self.odom_stamp).nanoseconds * 1e-9

    def _diagnostics(self):
        """(level, message, values): ERROR without a usable library, WARN while waiting."""
        S = self._Status
        blocked = self._state()
        level = OK if blocked is None or blocked[0] in (S.STATE_IDLE, S.STATE_GOAL_REACHED) else \
            ERROR if blocked[0] == S.STATE_ERROR else WARN
        message = f"following the {self.path.name} path" if blocked is None else blocked[1]
        values = {"library_file": self.cfg["library_file"], "path": self.path.name,
                  "progress": float(self.planner.progress) if self.planner is not None else 0.0,
                  "odometry_topic": self.resolve_topic_name(self.cfg["odom_topic"]),
                  "stale_decisions": self.stale_decisions, "pose_age_s": self.pose_age(),
                  "transitions": self.cfg["transitions"], "simulator_decisions": self.simulator_decisions,
                  "fallback_decisions": self.fallback_decisions, "last_rollout_s": self.last_rollout_s}
        return level, message, values

    def _publish(self, primitive_id: int, name: str, state: int, message: str, decision=None, now=None) -> None:
        now = self.get_clock().now() if now is None else now
        stamp = now.to_msg()
        msg = self._Primitive(id=primitive_id, name=name)
        msg.header.stamp = stamp
        msg.header.frame_id = self.cfg["world_frame"]
        self.primitive_pub.publish(msg)
        nan = float("nan")
        status = self._Status(primitive_id=primitive_id, primitive_name=name, state=state, message=message,
                              total_cost=nan, cost_distance=nan, cost_heading=nan, cost_progress=nan,
                              distance_to_path=nan, predicted_pose=Pose2D(x=nan, y=nan, theta=nan),
                              pose_age=self.pose_age(now))
        status.header.stamp, status.header.frame_id = stamp, self.cfg["world_frame"]
        if decision is not None:
            w = self.settings.weights
            t = decision.cost_terms
            status.total_cost = float(decision.total_cost)
            # unweighted terms; a zero weight leaves its term unknown rather than a fake 0
            status.cost_distance = t.distance / w.distance if w.distance else nan
            status.cost_heading = t.heading / w.heading if w.heading else nan
            status.cost_progress = t.progress / w.progress if w.progress else nan
            x, y, th = (float(v) for v in decision.predicted_pose)
            status.predicted_pose = Pose2D(x=x, y=y, theta=th)
            status.path_progress = float(decision.progress)
            status.distance_to_path = float(decision.distance_to_path)
        elif self.planner is not None:
            status.path_progress = float(self.planner.progress)
        limit, ahead, tight = self.feasibility(status.path_progress)
        status.turn_radius_limit, status.path_radius_ahead, status.path_too_tight = limit, ahead, tight
        if tight and state == self._Status.STATE_FOLLOWING:
            status.message = (f"{message}; the path ahead bends at r {ahead * 100:.1f} cm, tighter than the "
                              f"frog's {limit * 100:.1f} cm turn: cutting")
        self.status_pub.publish(status)

    def _log_state(self, state: int, message: str) -> None:
        # once per state and reason: the ages in a reason ("stale (3.12 s old)") do not count
        key = (state, re.sub(r"-?\d+(\.\d+)?", "#", message))
        if key == self._last_state:
            return
        text = message if state == self._Status.STATE_FOLLOWING else message + "; publishing primitive I"
        # rclpy wants one severity per call site
        if state == self._Status.STATE_ERROR:
            self.get_logger().error(text)
        elif state == self._Status.STATE_WAITING:
            self.get_logger().warning(text)
        else:
            self.get_logger().info(text)
        self._last_state = key

    def decide(self) -> None:
        S = self._Status
        if self._path_unstamped:
            self.publish_path()
        if self.pending is not None:            # a deadline the clock skipped past: close it first
            self.finish_simulator_decision()
        blocked = self._state()
        if blocked is None and self.cfg["transitions"] == "simulator":
            self.start_simulator_decision()
            return
        if blocked is None and self.cfg["replan_interval"] > 0:
            self.execute_queued()
            return
        if blocked is None:
            pose, velocity = self.odom
            try:
                d = self.planner.decide(pose, velocity)
            except ValueError as exc:
                blocked = S.STATE_ERROR, f"planner rejected the state: {exc}"
            else:
                # checked again when the decision is ready, which is also its stamp: on a loaded
                # machine deciding takes long enough for a pose at the bound to pass it meanwhile
                now = self.get_clock().now()
                blocked = self._state(now)
        if blocked is None:
            self._act(d, now, "following")
            return
        self._refuse(blocked)

    def _act(self, d, now, note: str) -> None:
        """Publish decision ``d`` (I when it reached the goal)."""
        S = self._Status
        if d.goal_reached:
            self.goal_reached = True
            message = (f"goal reached (progress {d.progress:.3f}, {d.distance_to_path * 100:.2f} cm "
                       f"from the path)")
            self._log_state(S.STATE_GOAL_REACHED, message)
            self._publish(self._Primitive.ID_I, NO_ACTION, S.STATE_GOAL_REACHED, message, now=now)
            return
        self._log_state(S.STATE_FOLLOWING, f"following the {self.path.name} path")
        self.get_logger().debug(f"primitive {d.name}: cost {d.total_cost:.2f}, progress {d.progress:.3f}")
        self._publish(d.primitive_id, d.name, S.STATE_FOLLOWING, note, d, now=now)

    def _refuse(self, blocked) -> None:
        state, reason = blocked
        if state == self._Status.STATE_WAITING:  # only odometry problems wait
            self.stale_decisions += 1           # a decision refused for a stale or missing pose
        self._log_state(state, reason)
        self._publish(self._Primitive.ID_I, NO_ACTION, state, reason)

    # -- the paper's asynchronous loop (replan_interval > 0) -----------------------------------------
    def replan(self) -> None:
        """Decide on the mean of the odometry since the last decision; queue it for the next tick."""
        if self._state() is not None:
            self.window.clear()                 # stopped or stale: nothing old goes into a later mean
            self.queued = None
            return
        if self.window.count == 0:
            return
        pose, velocity, n = self.window.mean()
        self.window.clear()
        try:
            d = self.planner.decide(pose, velocity)
        except ValueError as exc:
            self.get_logger().error(f"planner rejected the mean state: {exc}", throttle_duration_sec=2.0)
            return
        self.queued = (d, self.odom_stamp, n)

    def execute_queued(self) -> None:
        """At the tick: publish the newest queued decision once (as the authors' executor took it off
        its queue), unless there is none since the last tick or its pose is stale."""
        S = self._Status
        now = self.get_clock().now()
        if self.queued is None:
            self._refuse((S.STATE_WAITING, "no new decision queued since the last tick (replan_interval)"))
            return
        (d, stamp, n), self.queued = self.queued, None
        age = (now - stamp).nanoseconds * 1e-9
        bound = self.cfg["stale_periods"] * self.settings.period
        if age > bound:
            self._refuse((S.STATE_WAITING, f"the queued decision's pose is stale ({age:.2f} s; bound {bound:.2f} s)"))
            return
        self._act(d, now, f"following (queued decision on the mean of {n} poses, newest {age:.2f} s old)")

    # -- transitions: simulator ----------------------------------------------------------------
    def start_simulator_decision(self) -> None:
        """Ask for the rollouts of this tick's state; the decision is made at the deadline."""
        from rclpy.duration import Duration
        delay = self.cfg["decision_deadline"] * self.settings.period
        pose, velocity = self.odom
        depth = self.settings.depth
        firsts = ()
        if depth == 2 and 0 < self.cfg["beam_width"] < self.model.n_primitives:
            ranked = self.planner.rank_first_actions(pose, velocity)
            firsts = [self.model.primitive_names[i] for i in ranked[:self.cfg["beam_width"]]]
        execute_at = self.get_clock().now() + Duration(seconds=delay)
        lead = lead_time(execute_at, self.odom_stamp)
        future, reason = self.rollouts.request(pose, velocity, self.odom_stamp, self.settings.period, depth, lead,
                                               firsts)
        self.pending = {"future": future, "reason": reason, "pose": pose, "velocity": velocity,
                        "stamp": self.odom_stamp, "depth": depth, "lead": lead}
        self._deadline_timer = self.create_timer(delay, self.finish_simulator_decision)

    def finish_simulator_decision(self) -> None:
        """At the deadline: decide on the rollouts if they came, else on the library (WARN, counted)."""
        S = self._Status
        if self._deadline_timer is not None:
            self.destroy_timer(self._deadline_timer)
            self._deadline_timer = None
        pend, self.pending = self.pending, None
        if pend is None:
            return
        now = self.get_clock().now()
        expander, reason, future = None, pend["reason"], pend["future"]
        if future is not None:
            if future.done():
                try:
                    response = future.result()
                except Exception as exc:           # noqa: BLE001 - a failed call is a fallback, not a crash
                    reason = f"rollout call failed: {exc}"
                else:
                    self.last_rollout_s = float(response.compute_time)
                    expander, reason = RolloutClient.expander(response, self.model.primitive_names, pend["depth"],
                                                              self.cfg["reanchor"])
            else:
                reason = (f"rollouts missed the deadline ({self.cfg['decision_deadline']:.2f} periods = "
                          f"{self.cfg['decision_deadline'] * self.settings.period:.2f} s)")
                self.rollouts.cancel(future)
        blocked = self._state(now)
        bound = self.cfg["stale_periods"] * self.settings.period
        if blocked is None and (now - pend["stamp"]).nanoseconds * 1e-9 > bound:
            blocked = S.STATE_WAITING, (f"the rollouts' pose is stale at the deadline "
                                        f"({(now - pend['stamp']).nanoseconds * 1e-9:.2f} s; bound {bound:.2f} s)")
        if blocked is not None:
            self._refuse(blocked)
            return
        try:
            if expander is not None:
                pose, velocity = self.odom if self.cfg["reanchor"] else (pend["pose"], pend["velocity"])
                d = self.planner.decide(pose, velocity, expander)
                self.simulator_decisions += 1
                note = f"following (simulator, depth {pend['depth']}, lead {pend['lead']:.4f} s)"
            else:
                self.fallback_decisions += 1
                if reason != self._last_fallback:
                    self.get_logger().warning(f"library decision instead of the simulator's: {reason} "
                                              f"({self.fallback_decisions} so far)")
                self._last_fallback = reason
                pose, velocity = self.odom            # the newest pose: the library needs no lead
                d = self.planner.decide(pose, velocity)
                note = f"following (library fallback: {reason})"
        except ValueError as exc:
            self._refuse((S.STATE_ERROR, f"planner rejected the state: {exc}"))
            return
        if expander is not None:
            self._last_fallback = None
        self._act(d, now, note)


    def destroy_node(self):
        if self.simulator_decisions or self.fallback_decisions:     # the run's count, for reports
            self.get_logger().info(f"decisions: {self.simulator_decisions} simulator, {self.fallback_decisions} "
                                   f"library fallbacks")
        return super().destroy_node()


def main(args=None) -> int:
    return run_node(PlannerNode, args)


if __name__ == "__main__":
    sys.exit(main())
