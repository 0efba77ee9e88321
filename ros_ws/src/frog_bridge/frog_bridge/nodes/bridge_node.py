"""``bridge_node``: primitives and limb commands to the robot's serial relay, IMU and faults back.

Subscribes ``frog/primitive`` (soft_robot_interfaces/Primitive) and ``frog/limb_command``
(LimbActivation, direct limb commands from tools; not ``frog/limb_activation``, which is
what the robot fired and would loop back from the emulator), writes ``p``/``h`` lines to
the serial port, publishes every line it wrote on ``frog/bridge/sent`` (LimbActivation,
stamped at the write, with the stamp of the state its command was decided on and that
state's age at the write), the robot's orientation on ``frog/imu`` (sensor_msgs/Imu) and the
link's health on ``diagnostics``. It is the last hop before the hardware: a command whose
state (``state_stamp``; a command without one is its own state) would be older than
``max_state_age_s`` when its pulses are written is refused, and a pending pulse whose state
has aged past it is dropped (``refused_state_age`` in diagnostics), whatever the planner did.
An ``EMERGENCY`` line stops all actuation until
``~/clear_emergency`` (std_srvs/Trigger); so does a message on ``frog/stop``
(std_msgs/Empty, the run's one stop: the planner stops deciding and the bridge cancels
every pending pulse at once). Its own watchdog: when no ``frog/primitive`` (I included) has
come for ``primitive_timeout_s`` of node-clock time (simulated time in the twin) after one
had, every pending pulse is cancelled, a warning is logged once and the diagnostics say WARN
until a fresh primitive arrives, which is executed normally. The protocol, the limb
protection, the watchdog and the link state machine are in :mod:`frog_bridge.core`.
"""

from __future__ import annotations

import gc
import math
import statistics
import sys
import time
from collections import Counter, deque

from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.time import Time
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Imu
from soft_robot_common import (ConfigurationError, MessageGate, NodeDiagnostics, Param, declare_parameters,
                               params_from_dataclass, run_node)
from std_msgs.msg import Empty
from std_srvs.srv import Trigger

from frog_common.primitives import PRIMITIVE_NAMES, limb_label
from frog_common.state_age import StateAgeSettings
from frog_common.settings import from_params
from soft_robot_common.link_state import LinkState, LinkSupervisor
from frog_bridge.core.protection import LimbGuard, ProtectionConfig
from frog_bridge.core.protocol import (
    QUATERNION_ORDERS, DecodeError, Emergency, LineFramer, Quaternion, RelayText, decode_relay_line,
    encode_heat, encode_set_pulse, excerpt)
from frog_bridge.core.schedule import (
    CANCELLED_EMERGENCY, CANCELLED_LINK, CANCELLED_SHUTDOWN, CANCELLED_WATCHDOG, REFUSED_EMERGENCY, REFUSED_INVALID,
    REFUSED_LINK, REFUSED_STALLED, CommandScheduler)
from soft_robot_common.serial_link import SerialLink
from frog_bridge.core.watchdog import PrimitiveWatchdog, timeout_problem

PARAMS = [
    Param("port", "/dev/ttyACM0", "serial device of the nRF52 relay (a pty link for the emulator)"),
    Param("baud", 115200, "baud rate", min=1200, max=4_000_000),
    Param("pulse_ms", 80, "SMA heating pulse length sent once with 'p' [ms]; also the front-to-rear delay",
          min=10, max=500),
] + params_from_dataclass(ProtectionConfig) + params_from_dataclass(StateAgeSettings) + [
    Param("reconnect_period_s", 0.5, "first retry after the device is lost or fails to open [s]",
          min=0.05, max=60.0),
    Param("reconnect_max_period_s", 5.0, "retries back off (x2) up to this period [s]", min=0.05, max=600.0),
    Param("settle_s", 1.0, "wait after opening the port before writing to it [s]", min=0.0, max=30.0),
    Param("stall_timeout_s", 2.0, "no line from the relay for this long is reported as a stalled link [s]; "
          "0 = never", min=0.0, max=600.0),
    Param("stall_blocks_actuation", True, "refuse commands while the link is stalled (the relay or robot may not be "
          "receiving; lines written now could arrive late); set stall_timeout_s 0 for a robot that sends no lines"),
    Param("write_timeout_s", 0.05, "a line not written within this is a lost link [s]", min=0.001, max=5.0),
    Param("max_line_bytes", 256, "longer lines from the relay are discarded", min=16, max=65536),
    Param("quaternion_order", "wxyz", "order of the four numbers of a 'Central: Q' line",
          choices=QUATERNION_ORDERS),
    Param("quaternion_norm_tolerance", 0.1, "Q lines whose norm is further than this from 1 are refused",
          min=0.0, max=1.0),
    Param("imu_frame", "frog", "frame_id of frog/imu (the robot body frame)"),
    Param("orientation_variance", 0.0, "variance of each orientation angle [rad^2] for the Imu covariance; "
          "0 = unknown (all zeros, per sensor_msgs/Imu)", min=0.0, max=10.0),
    Param("diagnostics_period_s", 1.0, "period of diagnostics [s]", min=0.1, max=60.0),
    Param("primitive_timeout_s", 3.0, "watchdog: no frog/primitive (I included) for this long after one had "
          "arrived cancels every pending pulse (the planner is lost); a fresh primitive is executed normally "
          "[s, node clock]", min=0.1, max=3600.0, live=True),
]


def _validate(p: dict) -> str | None:
    if not p["port"].strip():
        return "port is empty: give the relay's serial device (e.g. /dev/ttyACM0)"
    if p["reconnect_max_period_s"] < p["reconnect_period_s"]:
        return (f"reconnect_max_period_s {p['reconnect_max_period_s']} must be >= reconnect_period_s "
                f"{p['reconnect_period_s']}")
    try:
        from_params(ProtectionConfig, p)
    except ValueError as exc:
        return str(exc)
    return None


def _stamp_s(stamp) -> float:
    """A stamp in seconds (0.0 for an unset stamp)."""
    return (stamp.sec * 1_000_000_000 + stamp.nanosec) * 1e-9


class BridgeNode(Node):
    """Serial bridge to the frog's BLE relay; parameters in :data:`PARAMS`."""

    NODE_NAME = "bridge_node"

    def __init__(self, **kwargs):
        super().__init__("bridge_node", **kwargs)
        self.gate = MessageGate(self)     # non-finite, unstamped or oversized inputs
        p = declare_parameters(self, PARAMS, validate=_validate, on_change=self._on_parameters)
        self.cfg = p
        from soft_robot_interfaces.msg import LimbActivation, Primitive
        self._LimbActivation = LimbActivation
        self.pulse_s = p["pulse_ms"] / 1000.0
        try:
            self.scheduler = CommandScheduler(
                LimbGuard(from_params(ProtectionConfig, p)),
                self.pulse_s, p["max_state_age_s"])
            supervisor = LinkSupervisor(p["reconnect_period_s"], p["reconnect_max_period_s"],
                                        p["settle_s"], p["stall_timeout_s"])
            self.watchdog = PrimitiveWatchdog(p["primitive_timeout_s"])
        except ValueError as exc:
            raise ConfigurationError(str(exc)) from exc
        self._warn_timeout(p["primitive_timeout_s"])
        self.framer = LineFramer(p["max_line_bytes"])
        self.counts: Counter[str] = Counter()           # lines and decode errors
        self.write_latency_ms: deque[float] = deque(maxlen=200)
        self.lost_at: float | None = None
        self.was_stalled = False
        self._due_timer = None
        self.stop_reason: str | None = None             # latched by frog/stop
        self._refusal_logged: dict[str, float] = {}     # refusal kind -> when last logged (steady) [s]
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)

        qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        self.sent_pub = self.create_publisher(LimbActivation, "frog/bridge/sent", qos)
        self.imu_pub = self.create_publisher(Imu, "frog/imu", qos)
        self.create_subscription(Primitive, "frog/primitive", self.on_primitive, qos)
        self.create_subscription(LimbActivation, "frog/limb_command", self.on_limb_command, qos)
        self.create_service(Trigger, "~/clear_emergency", self.on_clear_emergency)
        self.create_subscription(Empty, "frog/stop", self.on_stop, qos)

        # The reader thread wakes the executor: all protocol logic runs in the executor thread.
        self.link = SerialLink.for_node(self, self.on_link_events, p["port"], p["baud"], supervisor,
                                        p["write_timeout_s"])
        # Device supervision (settle, stall) runs on a steady clock: the device runs in real time
        # even when the graph runs on simulated time. Commands and stamps use the node clock.
        self.create_timer(0.1, self.supervise, clock=self._steady)
        self.diagnostics = NodeDiagnostics(self, "serial link", self._diagnostics, hardware_id=p["port"],
                                           period_s=p["diagnostics_period_s"])
        self.link.start()
        # Objects made so far live as long as the node: keep them out of the collector's full
        # passes, which otherwise add milliseconds to a write now and then.
        gc.freeze()
        self.get_logger().info(
            f"bridge to {p['port']} at {p['baud']} baud: pulse {p['pulse_ms']} ms, limb protection "
            f"{p['min_limb_interval_s']:g} s / {p['max_duty_cycle'] * 100:g} % of {p['duty_window_s']:g} s, "
            f"no pulse on a state older than {p['max_state_age_s']:g} s, watchdog {p['primitive_timeout_s']:g} s "
            f"without a primitive")

    def _on_parameters(self, changed: dict) -> None:
        if "max_state_age_s" in changed:
            self.scheduler.max_state_age_s = changed["max_state_age_s"]
        if "primitive_timeout_s" in changed:
            self.watchdog.timeout_s = changed["primitive_timeout_s"]
            self._warn_timeout(changed["primitive_timeout_s"])
            self._check_watchdog()

    def _warn_timeout(self, timeout_s: float) -> None:
        problem = timeout_problem(timeout_s, self.pulse_s)
        if problem:
            self.get_logger().warn(problem)

    # -- helpers -----------------------------------------------------------------------
    def _now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    # -- commands in -------------------------------------------------------------------
    def on_primitive(self, msg) -> None:
        t_in = time.perf_counter()
        problem = self.gate.problem(msg, stamped=False)   # a zero stamp on a command means now
        if problem:
            self._refuse_input("primitive", problem)
            return
        if msg.id >= len(PRIMITIVE_NAMES):
            self._refuse(REFUSED_INVALID, f"primitive id {msg.id} is out of range 0-8")
            return
        name = PRIMITIVE_NAMES[msg.id]
        if msg.name and msg.name.strip().upper() != name:
            self._refuse(REFUSED_INVALID, f"primitive id {msg.id} is {name!r} but the message names {msg.name!r}")
            return
        self._feed_watchdog()
        if not self._link_allows(f"primitive {name}"):
            return
        self._decided(self.scheduler.submit_primitive(msg.id, _stamp_s(msg.header.stamp), self._now(),
                                                      _stamp_s(msg.state_stamp)), t_in)

    def on_limb_command(self, msg) -> None:
        t_in = time.perf_counter()
        # a zero stamp on a command means now; a bad pulse length gets the scheduler's own message
        problem = self.gate.problem(msg, stamped=False) if math.isfinite(msg.pulse_duration) else None
        if problem:
            self._refuse_input("limb command", problem)
            return
        limbs = list(msg.limbs)
        self._check_watchdog()          # a silent planner's pulses go before this command is queued
        if not self._link_allows(f"limb command {limb_label(limbs)}"):
            return
        self._decided(self.scheduler.submit_limbs(limbs, _stamp_s(msg.header.stamp), self._now(),
                                                  msg.pulse_duration, _stamp_s(msg.state_stamp)), t_in)

    def _refuse_input(self, what: str, problem: str) -> None:
        """A message the common rule refuses (non-finite, oversized): counted, logged rate-limited."""
        self.scheduler.count_refusal(REFUSED_INVALID)
        if self.gate.should_log(what, problem):
            self.get_logger().warn(f"refused: {what}: {problem}")

    def _refuse(self, key: str, reason: str, throttle: bool = False) -> None:
        """Count a refusal and log it; ``throttle``: at most every 5 s per kind (``key``), so a stream of
        refusals is not logged each time but a refusal of another kind is logged at once."""
        self.scheduler.count_refusal(key)
        now = time.monotonic()
        if throttle and now - self._refusal_logged.get(key, -math.inf) < 5.0:
            return
        self._refusal_logged[key] = now
        self.get_logger().warn(f"refused: {reason}")

    def _link_allows(self, what: str) -> bool:
        if self.stop_reason is not None:
            self._refuse(REFUSED_EMERGENCY, f"{what}: {self.stop_reason} (call ~/clear_emergency)", throttle=True)
            return False
        if self.get_clock().now().nanoseconds == 0:
            self._refuse(REFUSED_LINK, f"{what}: the node clock has not started (use_sim_time and no /clock yet)",
                         throttle=True)
            return False
        link = self.link.snapshot()
        state, stalled, age = link.state, link.stalled, link.line_age
        if state is LinkState.READY and stalled and self.cfg["stall_blocks_actuation"]:
            since = "ever" if age is None else f"{age:.1f} s"
            self._refuse(REFUSED_STALLED, f"{what}: link stalled (no line from the relay for {since})", throttle=True)
            return False
        if state is LinkState.READY:
            return True
        if state is LinkState.EMERGENCY:
            self._refuse(REFUSED_EMERGENCY, f"{what}: emergency latched (call ~/clear_emergency)", throttle=True)
        else:
            self._refuse(REFUSED_LINK, f"{what}: link is {state.value}, nothing is queued", throttle=True)
        return False

    def _decided(self, decision, t_in: float) -> None:
        if not decision.accepted:
            reason = decision.reason
            self.get_logger().warn(reason if " refused: " in reason else f"refused: {reason}")
            return
        for c in decision.cancelled:
            self.get_logger().info(f"cancelled pending {c.label} pulse: a newer command heats the same limb")
        self._write_due(t_in)

    # -- watchdog ------------------------------------------------------------------------
    def _feed_watchdog(self) -> None:
        now = self._now()
        silence = self.watchdog.silence(now)
        if self.watchdog.fed(now):
            self.get_logger().info(f"primitives again after {silence:.2f} s without: watchdog cleared")
            self.diagnostics.publish()

    def _check_watchdog(self) -> None:
        """Trip the watchdog if the planner has been silent too long: cancel every pending pulse."""
        if self.get_clock().now().nanoseconds == 0:        # no /clock yet
            return
        now = self._now()
        if not self.watchdog.check(now):
            return
        n = len(self.scheduler.cancel_all(CANCELLED_WATCHDOG))
        self._arm_due_timer()
        self.get_logger().warn(f"no primitive for {self.watchdog.silence(now):.2f} s (planner lost?): {n} pending "
                               f"pulse(s) cancelled; a fresh primitive is executed normally")
        self.diagnostics.publish()

    # -- writing -------------------------------------------------------------------------
    def _write_due(self, t_in: float | None = None) -> None:
        t_in = time.perf_counter() if t_in is None else t_in
        self._check_watchdog()              # before any pulse: is the planner still there?
        to_write, stale = self.scheduler.pop_due(self._now())
        for p in stale:
            self.get_logger().warn(f"dropped {p.label} pulse: its state is {self._now() - p.state:.3f} s old at the "
                                   f"write (max_state_age_s {self.scheduler.max_state_age_s:g} s)")
        for p in to_write:
            problem = self.link.write_line(encode_heat(p.limbs))
            if problem:
                self.get_logger().error(f"{p.label} pulse not sent: {problem}")
                self.scheduler.count_refusal(CANCELLED_LINK)
                self.scheduler.cancel_all(CANCELLED_LINK)
                break
            self.write_latency_ms.append((time.perf_counter() - t_in) * 1e3)
            now = self.get_clock().now()
            self.scheduler.written(p, now.nanoseconds * 1e-9)
            self.counts["lines_written"] += 1
            msg = self._LimbActivation(limbs=list(p.limbs), pulse_duration=self.pulse_s,
                                       state_age=now.nanoseconds * 1e-9 - p.state)
            msg.header.stamp = now.to_msg()
            msg.state_stamp = Time(nanoseconds=round(p.state * 1e9), clock_type=now.clock_type).to_msg()
            self.sent_pub.publish(msg)
            self.get_logger().debug(f"sent {p.label}: h {' '.join(map(str, p.limbs))}")
        self._arm_due_timer()

    def _arm_due_timer(self) -> None:
        if self._due_timer is not None:
            self.destroy_timer(self._due_timer)
            self._due_timer = None
        due = self.scheduler.next_due()
        if due is not None:
            self._due_timer = self.create_timer(max(due - self._now(), 1e-4), self._on_due_timer)

    def _on_due_timer(self) -> None:
        self._write_due()

    # -- link events (from the reader thread, through the guard condition) ------------------
    def on_link_events(self) -> None:
        for ev in self.link.events():
            if ev.kind == "data":
                self._on_data(ev.data, ev.at)
            elif ev.kind == "opened":
                self.framer.reset()
                self.get_logger().info(f"opened {ev.text}; writing after {self.cfg['settle_s']:g} s")
            elif ev.kind == "lost":
                self.lost_at = ev.at
                n = len(self.scheduler.cancel_all(CANCELLED_LINK))
                self._arm_due_timer()
                lo, hi = self.cfg["reconnect_period_s"], self.cfg["reconnect_max_period_s"]
                self.get_logger().error(f"serial link lost ({ev.text}); {n} pending pulse(s) cancelled, "
                                        f"retrying every {lo:g}-{hi:g} s")
                self.diagnostics.publish()
            elif ev.kind == "open_failed":
                self.get_logger().warn(f"cannot open {self.cfg['port']}: {ev.text}; retrying",
                                       throttle_duration_sec=10.0)

    def _on_data(self, data: bytes, at: float) -> None:
        for item in self.framer.feed(data):
            if isinstance(item, DecodeError):
                self._decode_error(item)
                continue
            self.link.line_received(at)
            self.counts["lines_received"] += 1
            r = decode_relay_line(item, self.cfg["quaternion_order"], self.cfg["quaternion_norm_tolerance"])
            if isinstance(r, Quaternion):
                self._publish_imu(r)
            elif isinstance(r, Emergency):
                self._emergency(r.text)
            elif isinstance(r, RelayText):
                self.counts["other_lines"] += 1
                self.get_logger().debug(f"relay: {excerpt(r.text, 120)}")
            else:
                self._decode_error(r)

    def _decode_error(self, err: DecodeError) -> None:
        self.counts["decode_errors"] += 1
        self.counts[f"decode_error_{err.kind.value}"] += 1
        self.get_logger().warn(f"bad line from the relay: {err}", throttle_duration_sec=2.0)

    def _publish_imu(self, q: Quaternion) -> None:
        self.counts["imu_lines"] += 1
        msg = Imu()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = self.cfg["imu_frame"]
        o = msg.orientation
        o.w, o.x, o.y, o.z = q.w, q.x, q.y, q.z
        var = self.cfg["orientation_variance"]
        msg.orientation_covariance = [var, 0.0, 0.0, 0.0, var, 0.0, 0.0, 0.0, var]
        # sensor_msgs/Imu: element 0 = -1 marks a quantity the sensor does not report
        msg.angular_velocity_covariance[0] = -1.0
        msg.linear_acceleration_covariance[0] = -1.0
        self.imu_pub.publish(msg)

    def _emergency(self, text: str) -> None:
        new = self.link.emergency(text)
        self.counts["emergency_lines"] += 1
        if new:
            n = len(self.scheduler.cancel_all(CANCELLED_EMERGENCY))
            self._arm_due_timer()
            self.get_logger().error(f"robot reports {excerpt(text, 80)}: all actuation stopped ({n} pending "
                                    f"pulse(s) cancelled) until ~/clear_emergency")
            self.diagnostics.publish()

    def on_stop(self, msg) -> None:
        """frog/stop: cancel every pending pulse now and refuse new ones until ~/clear_emergency."""
        n = len(self.scheduler.cancel_all(CANCELLED_EMERGENCY))
        self._arm_due_timer()
        if self.stop_reason is None:
            self.get_logger().warn(f"stop received on {self.resolve_topic_name('frog/stop')}: {n} pending pulse(s) "
                                   "cancelled, no actuation until ~/clear_emergency")
        self.stop_reason = "stopped by frog/stop"

    def on_clear_emergency(self, request, response):
        stopped, self.stop_reason = self.stop_reason, None
        if stopped:
            self.get_logger().info("stop cleared")
        was = self.link.clear_emergency()
        state = self.link.snapshot().state
        response.success = True
        if was:
            response.message = f"emergency cleared; link is {state.value}"
            self.get_logger().info(response.message)
            self.diagnostics.publish()
        else:
            response.message = f"no emergency was latched; link is {state.value}"
        return response

    # -- supervision -----------------------------------------------------------------------
    def supervise(self) -> None:
        self._check_watchdog()
        now = time.monotonic()
        if self.link.settled(now):
            # "\n" ends any partial line an interrupted write left in the relay's buffer
            problem = self.link.write_line(b"\n" + encode_set_pulse(self.cfg["pulse_ms"]))
            if problem:
                self.get_logger().error(f"initialisation failed: {problem}")
                return
            self.link.ready(now)
            state = self.link.snapshot(now).state
            self.counts["lines_written"] += 1
            after = f" (reconnected {now - self.lost_at:.2f} s after the loss)" if self.lost_at else ""
            self.get_logger().info(f"link ready: sent 'p {self.cfg['pulse_ms']}'{after}; state {state.value}")
            self.lost_at = None
            self.diagnostics.publish()
        link = self.link.snapshot(now)
        stalled, age = link.stalled, link.line_age
        if stalled != self.was_stalled:
            self.was_stalled = stalled
            if stalled:
                self.get_logger().warn(f"link stalled: no line from the relay for "
                                       f"{'ever' if age is None else f'{age:.1f} s'}")
            else:
                self.get_logger().info("link alive again: lines from the relay resumed")

    def _diagnostics(self):
        """(level, message, values) of the link, the watchdog and the refusals (NodeDiagnostics)."""
        link = self.link.snapshot()
        state, stalled, age = link.state, link.stalled, link.line_age
        problem, losses, emergency = link.last_problem, link.losses, link.emergency_text
        if state is LinkState.EMERGENCY:
            level, message = DiagnosticStatus.ERROR, f"EMERGENCY latched: {emergency}; call ~/clear_emergency"
        elif state is LinkState.DISCONNECTED:
            level, message = DiagnosticStatus.ERROR, f"disconnected: {problem}; retrying"
        elif state is LinkState.CONNECTING:
            level, message = DiagnosticStatus.WARN, "connecting"
        elif stalled:
            level, message = DiagnosticStatus.WARN, f"ready but stalled: no line for {age:.1f} s" if age else \
                "ready but stalled: no line received yet"
        else:
            level, message = DiagnosticStatus.OK, "ready"
        silence = self.watchdog.silence(self._now())
        if self.watchdog.tripped and level == DiagnosticStatus.OK:
            level, message = DiagnosticStatus.WARN, (f"ready, but no primitive for {silence:.1f} s (planner lost?): "
                                                     f"pending pulses cancelled")
        lat = list(self.write_latency_ms)
        values = {
            "state": state.value, "port": self.cfg["port"], "stalled": str(stalled).lower(),
            "last_line_age_s": "nan" if age is None else f"{age:.3f}", "link_losses": str(losses),
            "bytes_read": str(link.bytes_read), "bytes_written": str(link.bytes_written),
            "write_latency_ms_median": f"{statistics.median(lat):.3f}" if lat else "nan",
            "write_latency_ms_max": f"{max(lat):.3f}" if lat else "nan",
            "emergency": emergency,
            "primitive_age_s": "nan" if silence is None else f"{silence:.3f}",
            "watchdog": "tripped" if self.watchdog.tripped else "ok" if silence is not None else "waiting",
            "watchdog_trips": str(self.watchdog.trips),
        }
        for k in ("lines_received", "lines_written", "imu_lines", "emergency_lines", "other_lines", "decode_errors"):
            values[k] = str(self.counts[k])
        for k, v in sorted(self.counts.items()):
            if k.startswith("decode_error_"):
                values[k] = str(v)
        values["refused_total"] = str(sum(v for k, v in self.scheduler.counts.items() if "cancelled" not in k))
        for k, v in sorted(self.scheduler.counts.items()):
            values[("cancelled_" + k.replace("_cancelled", "")) if "cancelled" in k else f"refused_{k}"] = str(v)
        values["ready"] = str(state is LinkState.READY and not stalled).lower()
        return level, message, values

    def shutdown(self) -> None:
        """Cancel pending pulses (no new heating on the way out) and close the port."""
        n = len(self.scheduler.cancel_all(CANCELLED_SHUTDOWN))
        if n:
            self.get_logger().info(f"shutdown: {n} pending pulse(s) cancelled")
        self.link.stop()


def main(args=None) -> int:
    return run_node(BridgeNode, args, close=lambda node: node.shutdown())


if __name__ == "__main__":
    sys.exit(main())
