"""``sim_node``: the frog simulator as a ROS 2 node (the digital twin's world).

Runs :class:`frog_sim.core.simulation.FrogSimulation` paced against the wall clock
(``real_time_factor``; 0 = as fast as possible), publishes the ground truth on
``frog/sim/odom`` (nav_msgs/Odometry: COM pose in ``tank``, body-frame twist in ``frog``)
and the rod network on ``frog/sim/shape`` (visualization_msgs/Marker, LINE_LIST), and
executes primitives (``frog/primitive``) and limb activations (``frog/limb_activation``); topic names are relative,
so ``__ns`` puts a second simulator beside the first.
With ``publish_clock`` it also publishes ``/clock`` (simulated time, monotonic across
``~/reset``) and stamps everything with it, so other nodes can run with ``use_sim_time``
faster than real time; otherwise stamps come from the node's ROS clock (system time).
``paused`` (live; the fault injector's clock stall) stops the simulation, its messages and
``/clock`` while true; it continues from the same time afterwards, without catching up. A lag
longer than ``max_lag_s`` (the process starved or blocked) is not caught up either
(:class:`frog_sim.core.pacing.Pacer`).
"""

from __future__ import annotations

import copy
import math
import sys
import time


from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point, TransformStamped
from nav_msgs.msg import Odometry
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from soft_robot_common import (ConfigurationError, MessageGate, NodeDiagnostics, Param, declare_parameters,
                               params_from_dataclass, run_node)
from soft_robot_common.diagnostics import ERROR, OK, WARN
from std_srvs.srv import Trigger
from visualization_msgs.msg import Marker

from frog_sim.core.model_parameters import FrogParameters
from frog_sim.core.pacing import Pacer
from frog_common.primitives import LIMB_NAMES, PRIMITIVE_NAMES
from frog_sim.core.simulation import DEFAULT_TIME_STEP, ConvergenceError, FrogSimulation
from frog_common.se2 import yaw_quaternion

_NODE_PARAMS = [
    Param("real_time_factor", 1.0, "simulated seconds per wall second; 0 = as fast as possible", min=0.0,
          max=1000.0, live=True),
    Param("max_lag_s", 0.5, "wall seconds the simulation may fall behind real time and still catch up; a "
          "longer lag (the process starved or blocked) is dropped and the world continues from where it is, "
          "as a real one would, instead of racing; 0 = always catch up", min=0.0, max=60.0, live=True),
    Param("publish_clock", False, "publish /clock with the simulated time (for use_sim_time nodes); the "
          "stamps are then simulated time too"),
    Param("time_step", DEFAULT_TIME_STEP, "integrator time step dt [s]", min=1e-5, max=0.01),
    Param("odom_rate_hz", 50.0, "rate of frog/sim/odom in simulated time [Hz]", min=0.1, max=1000.0),
    Param("shape_rate_hz", 10.0, "rate of frog/sim/shape in simulated time [Hz]", min=0.1, max=200.0),
    Param("execute_primitives", True, "execute frog/primitive directly; false when a robot (emulator) fires the "
          "limbs through frog/limb_activation, as in the digital twin"),
    Param("command_delay_s", 0.0, "fire each executed frog/primitive this long after its stamp in simulated "
          "time (a zero stamp: after its arrival): the robot's relay, BLE and firmware between a decision and "
          "its firing, in a loop without the serial link, at the same simulated time whatever the wall-clock "
          "latencies; a primitive that arrives later than that fires at once (diagnostics late_commands); "
          "0 = at once [s]", min=0.0, max=5.0),
    Param("odom_alias_topic", "", "also publish the ground truth here (e.g. frog/odom for a vision-free "
          "loop); empty = off"),
    Param("odom_alias_yaw", 0.0, "the alias reports the frame of a tag turned by this yaw on the body [rad] "
          "(heading + yaw, twist rotated into it), as a tracker would with the tag mounted turned and no offset "
          "calibrated; the hardware replay uses the authors' robot's; 0 = the body frame", min=-math.pi, max=math.pi),
    Param("world_frame", "tank", "frame of poses (REP-105 world/odom frame)"),
    Param("body_frame", "frog", "robot body frame of the odometry's twist, x forward"),
    Param("publish_tf", True, "publish the true pose on tf as world_frame -> tf_frame (with the odometry)"),
    Param("tf_frame", "frog_true", "child frame of the true pose on tf (the tracker publishes world -> frog)"),
    Param("initial_x", 0.0, "initial centre-of-mass x [m]", min=-1e3, max=1e3),
    Param("initial_y", 0.0, "initial centre-of-mass y [m]", min=-1e3, max=1e3),
    Param("initial_heading", 0.0, "initial heading [rad]", min=-2 * math.pi, max=2 * math.pi),
    Param("gait_frequency_hz", 0.0, "swim a periodic gait at this frequency from the start (within the "
          "measured frequencies for the EGaIn ratio); 0 = no gait", min=0.0, max=5.0),
    Param("gait_phase_offset", 0.5, "rear-pair delay as a fraction of the gait cycle, [0, 1)", min=0.0,
          max=0.999),
    Param("gait_duration_s", 0.0, "stop the gait after this long [s]; 0 = forever", min=0.0, max=1e6),
    Param("limb_strength_sd", 0.0, "relative spread of the four limbs' kick strengths: each limb's factor is "
          "drawn once from N(1, sd^2) with seed (real limbs differ); 0 = nominal", min=0.0, max=0.5),
    Param("kick_strength_sd", 0.0, "relative spread of each firing's kick: every fired limb kicks with its strength "
          "times a factor drawn from N(1, sd^2) per firing (real kicks vary from one to the next); 0 = none",
          min=0.0, max=0.5),
    Param("yaw_disturbance_sd", 0.0, "stationary sd of a slowly varying yaw torque about the centre of mass "
          "(an Ornstein-Uhlenbeck process: the tank's circulation and drifts, identified by 'frog-sim disturbance' "
          "from the hardware runs) [N m]; 0 = none", min=0.0, max=1e-3),
    Param("yaw_disturbance_tau_s", 2.0, "its time constant [s]", min=0.05, max=100.0),
    Param("seed", 0, "random seed of the limb strengths, the kick variability and the yaw disturbance", min=0,
          max=2**31 - 1),
    Param("paused", False, "stop simulating and publishing (odometry, shape, /clock: a clock stall) while true; "
          "continues from the same simulated time afterwards (live)", live=True),
    Param("duration_s", 0.0, "stop simulating (keep publishing the last state) after this simulated time "
          "[s]; 0 = run forever", min=0.0, max=1e7),
]

# Physical settings: every field of FrogParameters becomes parameter "model.<field>", with the
# range, unit and source its setting gives (frog_sim/core/model_parameters.py).

class SimNode(Node):
    """Frog simulator node; parameters in ``_NODE_PARAMS`` and ``model.*``."""

    NODE_NAME = "sim_node"

    def __init__(self, **kwargs):
        super().__init__("sim_node", **kwargs)
        self.gate = MessageGate(self)     # non-finite, unstamped or oversized commands are refused
        p = declare_parameters(self, _NODE_PARAMS, on_change=self.on_parameters)
        self.cfg = p
        model = declare_parameters(self, params_from_dataclass(FrogParameters), prefix="model.")
        try:
            params = FrogParameters(**model)
            self.sim = FrogSimulation(params, time_step=p["time_step"])
            self.sim.set_pose(p["initial_x"], p["initial_y"], p["initial_heading"])
            self.sim.set_realism(p["seed"], p["limb_strength_sd"], p["kick_strength_sd"], p["yaw_disturbance_sd"],
                                 p["yaw_disturbance_tau_s"])
            if p["gait_frequency_hz"] > 0:
                self.sim.set_gait(p["gait_frequency_hz"], p["gait_phase_offset"],
                                  duration=p["gait_duration_s"] or None)
        except (ValueError, TypeError) as exc:
            raise ConfigurationError(str(exc)) from exc

        qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        self.odom_pub = self.create_publisher(Odometry, "frog/sim/odom", qos)
        self.alias_pub = (self.create_publisher(Odometry, p["odom_alias_topic"], qos)
                          if p["odom_alias_topic"] else None)
        self.shape_pub = self.create_publisher(Marker, "frog/sim/shape", qos)
        # /clock is global by ROS convention (use_sim_time nodes listen there)
        self.clock_pub = self.create_publisher(Clock, "/clock", 10) if p["publish_clock"] else None
        self.tf_pub = None
        if p["publish_tf"]:
            try:
                from tf2_msgs.msg import TFMessage
            except ImportError:
                self.get_logger().warning("tf2_msgs is not installed: not publishing tf (build the workspace "
                                          "with ./dev, which provides it, or install ros-jazzy-tf2-msgs)")
            else:
                self._TFMessage = TFMessage
                self.tf_pub = self.create_publisher(TFMessage, "tf", 100)
        from soft_robot_interfaces.msg import LimbActivation, Primitive
        if p["execute_primitives"]:
            self.create_subscription(Primitive, "frog/primitive", self.on_primitive, qos)
        self.create_subscription(LimbActivation, "frog/limb_activation", self.on_activation, qos)
        self.create_service(Trigger, "~/reset", self.on_reset)

        # One time source: with publish_clock the node *is* the clock (simulated world time,
        # continuing across ~/reset); otherwise stamps come from the node's ROS clock.
        self.world_time_offset = 0.0      # simulated time before the last reset [s]
        self.odom_period = 1.0 / p["odom_rate_hz"]
        self.shape_period = 1.0 / p["shape_rate_hz"]
        self.next_odom = 0.0
        self.next_shape = 0.0
        self.error: str | None = None
        self.pacer = Pacer(p["real_time_factor"], p["max_lag_s"])
        self.pacer.anchor(time.monotonic(), self.sim.time)
        self._lag_logged = -math.inf       # wall time of the last lag warning (one per 10 s at most)
        self.steps_total = 0
        self.step_wall_s = 0.0
        self.late_commands = 0            # primitives that arrived after their stamp + command_delay_s
        self.create_timer(0.01, self.tick)
        self.diagnostics = NodeDiagnostics(self, "simulation", self._diagnostics, hardware_id="frog_sim",
                                           stamp=self._stamp)
        self.publish_state(force=True)
        self.get_logger().info(
            f"simulating the frog ({self.sim.model.n_nodes} nodes, EGaIn "
            f"{params.egain_vol_pct:g} %, dt {self.sim.time_step * 1e3:g} ms, real-time factor "
            f"{p['real_time_factor']:g}{', gait %.2f Hz' % p['gait_frequency_hz'] if p['gait_frequency_hz'] else ''}"
            f"; limb strengths " + ", ".join(f"{k} {v:.2f}" for k, v in self.sim.limb_strength.items()) + ")")

    def on_parameters(self, changed: dict) -> None:
        if "paused" in changed:
            if changed["paused"]:
                self.get_logger().warn(f"paused at simulated time {self.world_time:.3f} s: no simulation, "
                                       f"messages or /clock until paused is false")
            else:
                self.get_logger().info(f"resumed at simulated time {self.world_time:.3f} s")
        self.pacer.rtf, self.pacer.max_lag_s = self.cfg["real_time_factor"], self.cfg["max_lag_s"]
        if "real_time_factor" in changed or "paused" in changed:
            # re-anchor the pacing so the new rate applies from now on, without a jump (and the
            # diagnostics' real-time factors, which are measured since the anchor)
            self.pacer.anchor(time.monotonic(), self.sim.time)
            self.step_wall_s = 0.0

    # -- simulation loop -----------------------------------------------------------------
    def _target_time(self) -> float:
        target, dropped = self.pacer.target(time.monotonic(), self.sim.time)
        if dropped > 0:
            now = time.monotonic()
            if now - self._lag_logged >= 10.0:
                self._lag_logged = now
                self.get_logger().warning(
                    f"fell {dropped / self.pacer.rtf:.2f} s behind the wall clock at simulated time "
                    f"{self.world_time:.3f} s (the process was starved or blocked): continuing from there "
                    f"without catching up ({self.pacer.drops} lag(s) dropped, {self.pacer.dropped_total_s:.2f} "
                    f"simulated s in all; max_lag_s {self.pacer.max_lag_s:g})")
        return target

    def tick(self) -> None:
        if self.error is not None or self.cfg["paused"]:
            return
        end = self.cfg["duration_s"] or math.inf
        dt = self.sim.time_step
        if self.sim.time + 0.5 * dt >= end:     # done: no pacing (and no lag) any more
            return
        target = min(self._target_time(), end)
        budget_end = time.monotonic() + 0.05   # keep callbacks (commands) responsive
        while self.sim.time + 0.5 * dt < target and time.monotonic() < budget_end:
            # advance to the next publication time, at most to the target
            next_pub = min(self.next_odom, self.next_shape, target)
            n = max(1, int(round((next_pub - self.sim.time) / dt)))
            t0 = time.perf_counter()
            try:
                self.sim.step(n)
            except ConvergenceError as exc:
                self.error = f"simulation stopped at t = {self.sim.time:.3f} s: {exc}"
                self.get_logger().error(self.error + " (call ~/reset to start again)")
                return
            self.step_wall_s += time.perf_counter() - t0
            self.steps_total += n
            self.publish_state()

    @property
    def world_time(self) -> float:
        """Simulated time since the node started [s], monotonic across ~/reset."""
        return self.world_time_offset + self.sim.time

    def _stamp(self) -> Time:
        if self.clock_pub is None:
            return self.get_clock().now().to_msg()
        sec, nanosec = divmod(int(round(self.world_time * 1e9)), 1_000_000_000)
        return Time(sec=sec, nanosec=nanosec)

    def publish_state(self, force: bool = False) -> None:
        t = self.sim.time
        if self.clock_pub is not None:
            clock = Clock()
            clock.clock = self._stamp()
            self.clock_pub.publish(clock)
        if force or t + 1e-9 >= self.next_odom:
            self.next_odom = t + self.odom_period
            self.publish_odom()
        if force or t + 1e-9 >= self.next_shape:
            self.next_shape = t + self.shape_period
            self.publish_shape()

    def _alias(self, msg: Odometry, heading: float, forward: float, lateral: float) -> Odometry:
        """``msg`` as seen in a frame turned by ``odom_alias_yaw`` on the body (``msg`` itself at 0)."""
        yaw = self.cfg["odom_alias_yaw"]
        if yaw == 0.0:
            return msg
        alias = copy.deepcopy(msg)
        q = alias.pose.pose.orientation
        q.x, q.y, q.z, q.w = yaw_quaternion(heading + yaw)
        c, s = math.cos(yaw), math.sin(yaw)
        alias.twist.twist.linear.x, alias.twist.twist.linear.y = c * forward + s * lateral, -s * forward + c * lateral
        return alias

    def publish_odom(self) -> None:
        s = self.sim.rigid_body_state()
        msg = Odometry()
        msg.header.stamp = self._stamp()
        msg.header.frame_id = self.cfg["world_frame"]
        msg.child_frame_id = self.cfg["body_frame"]
        msg.pose.pose.position.x, msg.pose.pose.position.y = float(s.com[0]), float(s.com[1])
        (msg.pose.pose.orientation.x, msg.pose.pose.orientation.y, msg.pose.pose.orientation.z,
         msg.pose.pose.orientation.w) = yaw_quaternion(float(s.heading))
        forward, lateral = (float(v) for v in s.body_velocity)
        # REP-105: twist is expressed in the child (body) frame
        msg.twist.twist.linear.x, msg.twist.twist.linear.y = forward, lateral
        msg.twist.twist.angular.z = float(s.yaw_rate)
        self.odom_pub.publish(msg)
        if self.alias_pub is not None:
            self.alias_pub.publish(self._alias(msg, float(s.heading), forward, lateral))
        if self.tf_pub is not None:
            tf = TransformStamped()
            tf.header = msg.header
            tf.child_frame_id = self.cfg["tf_frame"]
            tf.transform.translation.x = msg.pose.pose.position.x
            tf.transform.translation.y = msg.pose.pose.position.y
            tf.transform.rotation = msg.pose.pose.orientation
            self.tf_pub.publish(self._TFMessage(transforms=[tf]))

    def publish_shape(self) -> None:
        pos = self.sim.node_positions
        edges = self.sim.model.network.edges
        msg = Marker()
        msg.header.stamp = self._stamp()
        msg.header.frame_id = self.cfg["world_frame"]
        msg.ns, msg.id = "frog_rods", 0
        msg.type, msg.action = Marker.LINE_LIST, Marker.ADD
        msg.pose.orientation.w = 1.0
        msg.scale.x = 0.002                      # line width [m]
        msg.color.r, msg.color.g, msg.color.b, msg.color.a = 0.1, 0.6, 0.2, 1.0
        ends = pos[edges.ravel()]
        msg.points = [Point(x=float(x), y=float(y), z=0.0) for x, y in ends]
        self.shape_pub.publish(msg)

    # -- commands ------------------------------------------------------------------------
    def on_primitive(self, msg) -> None:
        if self.gate.refused("frog/primitive", msg, stamped=False):
            return
        if msg.id >= len(PRIMITIVE_NAMES):
            self.get_logger().error(f"rejected primitive id {msg.id}: out of range 0-8")
            return
        name = PRIMITIVE_NAMES[msg.id]
        if msg.name and msg.name.strip().upper() != name:
            self.get_logger().error(f"rejected primitive: id {msg.id} is {name!r} but the "
                                    f"message names {msg.name!r}")
            return
        if self.error is None:
            start = self.firing_time(msg.header.stamp)
            self.sim.execute_primitive(name, start=start)
            self.get_logger().debug(f"primitive {name} at t = {self.sim.time:.3f} s, fired at "
                                    f"{self.sim.time if start is None else start:.3f} s")

    def firing_time(self, stamp) -> float | None:
        """Simulated time [s] to fire a command stamped ``stamp``: ``command_delay_s`` after the stamp
        (after now for a zero stamp or without simulated stamps), at once if that has passed; None
        (at once) without a delay."""
        delay = self.cfg["command_delay_s"]
        if delay <= 0.0:
            return None
        ref = self.sim.time
        t = stamp.sec + 1e-9 * stamp.nanosec
        if self.clock_pub is not None and t > 0.0:
            ref = t - self.world_time_offset
        if ref + delay < self.sim.time:
            self.late_commands += 1
            return self.sim.time
        return ref + delay

    def on_activation(self, msg) -> None:
        limbs = list(msg.limbs)
        if any(i >= len(LIMB_NAMES) for i in limbs) or len(set(limbs)) != len(limbs):
            self.get_logger().error(f"rejected limb activation {limbs}: ids must be distinct "
                                    f"and in 0-3 (FL 0, FR 1, BL 2, BR 3)")
            return
        if not (math.isfinite(msg.pulse_duration) and 0 <= msg.pulse_duration <= 1.0):
            self.get_logger().error(f"rejected limb activation: pulse_duration "
                                    f"{msg.pulse_duration!r} s must be in [0, 1]")
            return
        if self.gate.refused("frog/limb_activation", msg, stamped=False):
            return
        if limbs and self.error is None:
            # The measured curvature profile already contains the hardware pulse.
            self.sim.fire_limbs([LIMB_NAMES[i] for i in limbs])

    def on_reset(self, request, response):
        p = self.cfg
        # the reset state is one step after the last state published: stamps strictly increase
        self.world_time_offset += self.sim.time + self.sim.time_step
        self.sim.reset()
        self.sim.set_pose(p["initial_x"], p["initial_y"], p["initial_heading"])
        if p["gait_frequency_hz"] > 0:
            self.sim.set_gait(p["gait_frequency_hz"], p["gait_phase_offset"],
                              duration=p["gait_duration_s"] or None)
        self.error = None
        self.next_odom = self.next_shape = 0.0
        self.pacer.anchor(time.monotonic(), self.sim.time)
        self.step_wall_s = 0.0
        self.publish_state(force=True)
        response.success, response.message = True, "simulation reset to the initial pose"
        self.get_logger().info(f"reset to the initial pose at world time {self.world_time:.3f} s")
        return response

    def _diagnostics(self):
        achieved = self.pacer.achieved_rtf(time.monotonic(), self.sim.time)
        sim_elapsed = self.sim.time - self.pacer.sim_start
        level = ERROR if self.error else WARN if self.cfg["paused"] else OK
        message = self.error or ("paused (a clock stall): set paused false to continue" if self.cfg["paused"]
                                 else "running")
        cost = self.step_wall_s / sim_elapsed if sim_elapsed > 0 else float("nan")
        return level, message, {
            "sim_time_s": f"{self.sim.time:.3f}", "achieved_real_time_factor": f"{achieved:.2f}",
            "compute_real_time_factor": f"{1 / cost:.1f}" if cost > 0 else "nan", "steps": self.steps_total,
            "lags_dropped": self.pacer.drops, "lag_dropped_s": f"{self.pacer.dropped_total_s:.3f}",
            "paused": bool(self.cfg["paused"]), "late_commands": self.late_commands,
            "ready": self.error is None}


def main(args=None) -> int:
    return run_node(SimNode, args)


if __name__ == "__main__":
    sys.exit(main())
