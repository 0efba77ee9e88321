"""kinematics_node: FK/IK services, streamed tip targets and the FollowCurve action for a soft robot.

Interfaces (relative names; the finger's defaults resolve under ``/finger``):

* service ``finger/forward_kinematics`` (ForwardKinematics): actuation -> markers and tip;
* service ``finger/solve_ik`` (SolveIk): tip target -> actuation, warm started from the last
  query (or the nearest configuration sample); a query only, nothing is actuated;
* subscription ``finger/target`` (PointStamped in ``frame_id``): IK warm started from the last
  command, then ``finger/tendon_setpoints`` (JointState: cable pull from rest [m] per cable),
  ``finger/tip`` (PointStamped: FK of the command) and ``finger/shape`` (Marker);
  a newer target supersedes one still waiting for the solver;
* action ``finger/follow_curve`` (FollowCurve): Algorithm 3 with feedback per waypoint,
  cancellable between waypoints; each waypoint's command is published as above.

All solves run on one worker thread (``core.worker``); callbacks run on a multi-threaded
executor, so services, cancels and parameter calls stay responsive during a trajectory.
"""
from __future__ import annotations

import threading
import time

import numpy as np
from geometry_msgs.msg import Point, PointStamped
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from frog_common.settings import from_params
from soft_robot_common import (ConfigurationError, MessageGate, NodeDiagnostics, Param, declare_parameters,
                               params_from_dataclass, run_node)
from soft_robot_common.diagnostics import OK
from soft_robot_interfaces.action import FollowCurve
from soft_robot_interfaces.srv import ForwardKinematics, SolveIk
from visualization_msgs.msg import Marker

from ..core.kinematics import IKSettings, RequestError, RobotKinematics, check_tolerance, load_robot
from ..core.worker import SolverWorker

PARAMS = [
    Param("frame_id", "finger_base", "frame of the robot's base: targets, tip, shape and waypoints are in it"),
    Param("model", "finger", "built-in model (ignored when mesh_file is set)", choices=("finger", "pneumatic", "dea")),
    Param("resolution", 0, "mesh resolution of the built-in model; 0 = its default (finger: 2)", min=0, max=6),
    Param("mesh_file", "", "your own volume mesh (.msh, .vtu, ... or TetGen .node); needs spec_file"),
    Param("spec_file", "", "JSON spec of mesh_file: units, R_w regions, fixed vertices, actuators, markers"),
    Param("marker", "tip", "tracked marker (end effector) of the mesh"),
    Param("config_samples", 5, "configuration-space samples per actuator solved at start-up to seed IK "
          "(n^actuators FK solves; 0 = start from rest)", min=0, max=9),
] + params_from_dataclass(IKSettings) + [
    Param("max_target_distance", 0.0, "targets farther than this from the robot's rest bounding box are refused "
          "[m]; 0 = the box diagonal", min=0.0, max=100.0),
    Param("hold_rest_cables", False, "a cable at rest length that bending would stretch goes taut (its motor "
          "holds it); off: the core's model, in which the built-in curves were placed"),
    Param("publish_shape", True, "publish the deformed surface on finger/shape with commands"),
    Param("shape_period", 0.2, "least time between two finger/shape messages while streaming [s] (a trajectory's "
          "last shape is always sent)", min=0.0, max=10.0, live=True),
]

RELIABLE = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)


def _point(p) -> Point:
    return Point(x=float(p[0]), y=float(p[1]), z=float(p[2]))


class KinematicsNode(Node):
    NODE_NAME = "kinematics_node"

    def __init__(self):
        super().__init__(self.NODE_NAME)
        self.gate = MessageGate(self)     # non-finite, unstamped or oversized requests are refused
        p = self.p = declare_parameters(self, PARAMS, on_change=self._on_change)
        log = self.get_logger()
        t0 = time.perf_counter()
        try:
            mesh = load_robot(p["model"], p["resolution"], p["mesh_file"], p["spec_file"])
            log.info(f"loaded {mesh.info.get('model', 'mesh')}: {mesh.n_vertices} vertices, {mesh.n_tets} tets, "
                     f"actuators {[a.name for a in mesh.actuators]}; solving {p['config_samples']}^"
                     f"{len(mesh.actuators)} configuration samples (first solves compile numba kernels)")
            self.kin = RobotKinematics(
                mesh, marker=p["marker"], config_samples=p["config_samples"],
                settings=from_params(IKSettings, p),
                max_target_distance=p["max_target_distance"], hold_rest_cables=p["hold_rest_cables"])
        except RequestError as exc:
            raise ConfigurationError(str(exc)) from None
        if not self.kin.all_cables:
            log.warn("not all actuators are cables: finger/tendon_setpoints is not published")
        self.frame = p["frame_id"]
        self.worker = SolverWorker(on_error=lambda e: log.error(f"solve failed: {e!r}"))
        self._lock = threading.Lock()
        self._trajectory = False       # an action goal is running
        self._command_seq = 0          # bumped when a trajectory starts: older pending targets are stale
        self._last_query = None        # last SolveIk solution (service warm start)
        self._last_shape = 0.0
        self._closing = False
        self.pub_setpoints = self.create_publisher(JointState, "finger/tendon_setpoints", RELIABLE)
        self.pub_tip = self.create_publisher(PointStamped, "finger/tip", 10)
        self.pub_shape = self.create_publisher(Marker, "finger/shape", LATCHED)
        group = ReentrantCallbackGroup()
        self.create_subscription(PointStamped, "finger/target", self._on_target, 10)
        self.create_service(ForwardKinematics, "finger/forward_kinematics", self._srv_fk, callback_group=group)
        self.create_service(SolveIk, "finger/solve_ik", self._srv_ik, callback_group=group)
        self._action = ActionServer(self, FollowCurve, "finger/follow_curve", execute_callback=self._execute,
                                    goal_callback=self._goal, cancel_callback=lambda _: CancelResponse.ACCEPT,
                                    callback_group=group)
        self._stats = dict(solves=0, refused=0, last_solve_ms=0.0)
        self.diagnostics = NodeDiagnostics(self, "solver", self._diagnostics,
                                           hardware_id=str(self.kin.mesh.info.get("model", "mesh")))
        if p["publish_shape"]:
            self._publish_shape(self.kin.rest.positions)
        log.info(f"ready in {time.perf_counter() - t0:.1f} s: services finger/solve_ik, finger/forward_kinematics, "
                 f"action finger/follow_curve, targets on finger/target in frame '{self.frame}'")

    def _diagnostics(self):
        vals = dict(self._stats, superseded_targets=self.worker.superseded, vertices=self.kin.mesh.n_vertices,
                    actuators=",".join(self.kin.names), frame_id=self.frame, ready=True)
        vals["last_solve_ms"] = f"{vals['last_solve_ms']:.1f}"
        return OK, "trajectory running" if self._trajectory else "ready", vals

    def _on_change(self, changed: dict) -> None:
        self.kin.settings = from_params(IKSettings, self.p)

    def _solve(self, service: str, job, res):
        """``job()`` on the solver thread; None (``res`` says why, logged) if refused or failed."""
        try:
            return self.worker.call(job)
        except RequestError as exc:
            res.success, res.message = False, f"refused: {exc}"
        except Exception as exc:
            res.success, res.message = False, f"solver failed: {exc!r}"
        self.get_logger().error(f"{service} {res.message}")
        return None

    # --- publishing -----------------------------------------------------------------------
    def _publish_command(self, ik, stamp=None, final: bool = True) -> None:
        """Setpoints, tip and shape of a commanded IK solution (worker thread)."""
        stamp = stamp or self.get_clock().now().to_msg()
        if self.kin.all_cables:
            js = JointState()
            js.header.stamp = stamp
            js.name = list(self.kin.names)
            js.position = [float(v) for v in self.kin.pulls(ik.actuation)]
            self.pub_setpoints.publish(js)
        tip = PointStamped()
        tip.header.stamp, tip.header.frame_id = stamp, self.frame
        tip.point = _point(ik.reached[0])
        self.pub_tip.publish(tip)
        if self.p["publish_shape"] and (final or time.monotonic() - self._last_shape >= self.p["shape_period"]):
            self._publish_shape(ik.fk.positions, stamp)

    def _publish_shape(self, positions, stamp=None) -> None:
        self._last_shape = time.monotonic()
        m = Marker()
        m.header.stamp = stamp or self.get_clock().now().to_msg()
        m.header.frame_id = self.frame
        m.ns, m.id, m.type, m.action = "softkin_shape", 0, Marker.TRIANGLE_LIST, Marker.ADD
        m.pose.orientation.w = 1.0
        m.scale.x = m.scale.y = m.scale.z = 1.0
        m.color.r, m.color.g, m.color.b, m.color.a = 0.95, 0.55, 0.15, 1.0
        m.points = [Point(x=x, y=y, z=z) for x, y, z in positions[self.kin.faces].reshape(-1, 3).tolist()]
        self.pub_shape.publish(m)

    # --- streamed targets -----------------------------------------------------------------
    def _on_target(self, msg: PointStamped) -> None:
        log = self.get_logger()
        problem = self.gate.problem(msg, stamped=False)
        if problem:
            self._stats["refused"] += 1
            if self.gate.should_log("finger/target", problem):
                log.error(f"target refused: {problem}")
            return
        if msg.header.frame_id not in ("", self.frame):
            log.error(f"target refused: frame '{msg.header.frame_id}' is not the base frame '{self.frame}'")
            return
        try:
            p = self.kin.check_target([msg.point.x, msg.point.y, msg.point.z])
        except RequestError as exc:
            log.error(f"target refused: {exc}")
            self._stats["refused"] += 1
            return
        with self._lock:
            if self._trajectory:
                log.warn("target refused: a follow_curve goal is running (cancel it first)")
                return
            seq = self._command_seq
        if self.worker.submit_latest(lambda: self._solve_target(p, seq)):
            log.debug("a pending target was superseded by a newer one")

    def _solve_target(self, p, seq) -> None:
        with self._lock:
            if self._trajectory or seq != self._command_seq:
                return   # a trajectory started since: this target is stale
        t0 = time.perf_counter()
        r = self.kin.inverse(p, warm=self.kin.last)
        self.kin.last = r
        self._publish_command(r)
        dt = time.perf_counter() - t0
        self._stats["solves"] += 1
        self._stats["last_solve_ms"] = dt * 1e3
        if r.success:
            self.get_logger().debug(f"target reached within {r.error * 1e3:.3f} mm in {dt * 1e3:.0f} ms")
        else:
            self.get_logger().warn(f"target out of reach: moving to the nearest point found, "
                                   f"{r.error * 1e3:.2f} mm away")

    # --- services -------------------------------------------------------------------------
    def _srv_fk(self, req, res):
        problem = self.gate.problem(req, stamped=False)
        if problem:
            res.success, res.message = False, f"refused: {problem}"
            self.get_logger().error(f"forward_kinematics {res.message}")
            return res
        fk = self._solve("forward_kinematics", lambda: self.kin.forward(list(req.actuation)), res)
        if fk is None:
            return res
        names = sorted(self.kin.mesh.markers)
        res.marker_points = [_point(fk.positions[self.kin.mesh.markers[n]]) for n in names]
        res.tip = _point(fk.marker(self.kin.mesh, self.kin.marker))
        res.success = bool(fk.converged)
        res.message = (f"{'converged' if fk.converged else 'NOT converged'} in {fk.iterations} iterations; "
                       f"marker_points: {', '.join(names)}; tip = '{self.kin.marker}'")
        return res

    def _srv_ik(self, req, res):
        t = req.target
        try:
            check_tolerance(req.tolerance, self.kin.settings.lam)    # its own message first
            problem = self.gate.problem(req, stamped=False)
        except (RequestError, ValueError) as exc:
            problem = str(exc)
        if problem:
            res.success, res.message = False, f"refused: {problem}"
            self.get_logger().error(f"solve_ik {res.message}")
            return res

        def solve():
            r = self.kin.inverse([t.x, t.y, t.z], initial=list(req.initial_guess),
                                 warm=self._last_query or self.kin.last, lam=req.tolerance,
                                 i_max=int(req.max_iterations))
            self._last_query = r
            return r
        r = self._solve("solve_ik", solve, res)
        if r is None:
            return res
        res.success = bool(r.success)
        res.actuation = [float(v) for v in r.actuation]
        res.reached = _point(r.reached[0])
        res.residual_error = float(r.error)
        res.iterations = int(r.iterations)
        lam = check_tolerance(req.tolerance, self.kin.settings.lam)   # checked by the solve already
        res.message = (f"reached within {r.error * 1e3:.3f} mm" if r.success else
                       f"target out of reach: nearest point found is {r.error * 1e3:.3f} mm away "
                       f"(tolerance {lam * 1e3:.3f} mm)")
        return res

    # --- action ---------------------------------------------------------------------------
    def _goal(self, goal) -> GoalResponse:
        with self._lock:
            if self._trajectory:
                self.get_logger().error("follow_curve goal rejected: another goal is running")
                return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def _execute(self, goal_handle):
        g = goal_handle.request
        result = FollowCurve.Result()
        result.actuator_names = list(self.kin.names)
        with self._lock:
            busy = self._trajectory
            if not busy:
                self._trajectory = True
                self._command_seq += 1
        if busy:
            result.message = "another follow_curve goal is running"
            goal_handle.abort()
            return result
        try:
            return self._run_goal(goal_handle, g, result)
        finally:
            with self._lock:
                self._trajectory = False

    def _run_goal(self, goal_handle, g, result):
        log = self.get_logger()
        try:
            if g.frame_id not in ("", self.frame):
                raise RequestError(f"frame '{g.frame_id}' is not the base frame '{self.frame}'")
            lam = check_tolerance(g.tolerance, self.kin.settings.lam)
            P = self.kin.waypoints(g.curve, int(g.n_waypoints), [[w.x, w.y, w.z] for w in g.waypoints])
            problem = self.gate.problem(g, stamped=False)      # whatever the checks above did not see
            if problem:
                raise RequestError(problem)
        except RequestError as exc:
            result.message = f"goal refused: {exc}"
            log.error(f"follow_curve {result.message}")
            goal_handle.abort()
            return result
        log.info(f"follow_curve: {len(P)} waypoints ({g.curve or 'given'}), tolerance {lam * 1e3:.3f} mm"
                 + (" (dry run)" if g.dry_run else ""))

        def on_waypoint(i, r):
            fb = FollowCurve.Feedback(index=i, total=len(P), target=_point(P[i]), reached=_point(r.reached[0]),
                                      error=float(r.error), actuation=[float(v) for v in r.actuation],
                                      within_tolerance=bool(r.error <= lam))
            if not g.dry_run:
                self.kin.last = r
                self._publish_command(r, final=i == len(P) - 1)
            goal_handle.publish_feedback(fb)
            self.worker.serve_pending()   # services answered between waypoints
            return not (goal_handle.is_cancel_requested or self._closing)

        t0 = time.perf_counter()
        try:
            tr = self.worker.call(lambda: self.kin.follow(P, lam=lam, on_waypoint=on_waypoint))
        except Exception as exc:
            result.message = f"solver failed: {exc!r}"
            log.error(f"follow_curve {result.message}")
            goal_handle.abort()
            return result
        result.solve_seconds = time.perf_counter() - t0
        result.targets = [_point(q) for q in tr.targets]
        result.reached = [_point(q) for q in tr.reached]
        result.errors = [float(e) for e in tr.errors]
        result.actuations = [float(v) for v in np.asarray(tr.actuations).ravel()]
        result.waypoints_reached = int(np.sum(tr.errors <= lam))
        done = len(tr.targets)
        if self._closing and done < len(P):
            result.success = False
            result.message = f"node shutting down: stopped after {done} of {len(P)} waypoints"
            log.warn(f"follow_curve {result.message}")
            goal_handle.abort()
            return result
        if goal_handle.is_cancel_requested:
            result.success = False
            result.message = f"canceled after {done} of {len(P)} waypoints"
            log.info(f"follow_curve {result.message}")
            goal_handle.canceled()
            return result
        result.success = bool(result.waypoints_reached == len(P))
        result.message = (f"{result.waypoints_reached}/{len(P)} waypoints within {lam * 1e3:.3f} mm, largest error "
                          f"{tr.errors.max() * 1e3:.3f} mm, {result.solve_seconds:.2f} s")
        log.info(f"follow_curve done: {result.message}")
        goal_handle.succeed()
        return result

    def destroy_node(self):
        self._closing = True   # a running trajectory stops at its next waypoint
        self.worker.stop()
        self._action.destroy()
        return super().destroy_node()


def main(args=None):
    return run_node(KinematicsNode, args, executor=lambda: MultiThreadedExecutor(num_threads=4))


if __name__ == "__main__":
    import sys
    sys.exit(main())
