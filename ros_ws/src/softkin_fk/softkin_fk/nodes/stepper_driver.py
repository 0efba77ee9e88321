"""stepper_driver: tendon setpoints -> G-code for a Marlin board (Arduino Mega + RAMPS) over serial.

Subscribes to ``finger/tendon_setpoints`` (JointState: cable pull from rest [m] per cable, by
name), converts each pull to whole microsteps (``core.stepper``), and sends one ``G1`` per
setpoint whose feedrate makes all axes arrive together, the fastest cable at
``max_cable_speed``. The link follows Marlin's protocol (``core.marlin``): banner, ``M110``,
``G21`` (mm), ``G90`` (absolute), ``G92`` (the known position), numbered and checksummed lines,
``ok`` flow control with a window, ``Resend:`` handling. ``M114`` is polled and published as
``finger/stepper_state`` (JointState: the pulls the motors' reported step counts mean [m]);
``M400`` follows the last setpoint of a burst (trajectory end).

Fail safe: a setpoint with wrong names, NaN or a pull outside [min_pull, max_pull] is refused
whole and logged; nothing is queued while the link is down, so nothing stale is sent after a
reconnect. ``~/stop`` (std_srvs/Trigger) drops queued moves, quick-stops the board (``M410``)
and disables the motors (``M18``); setpoints are refused until ``~/resume``. Shutdown does the
same. A board reset (``start`` mid-session) or a vanished device is logged; the driver
reconnects, re-initialises and restores the last reported position with ``G92``.
``diagnostics``: link state, queue depth, lines in flight, errors, resends, refusals.

The port is a :class:`soft_robot_common.serial_link.SerialLink` (the bridge's design: its
thread reads and reconnects, the protocol runs in the executor). Link states: disconnected,
connecting (until the banner or ``banner_timeout``), ready, halted (Marlin's kill(), the
link's emergency latch, cleared by the board's reset banner or a reconnect).
"""
from __future__ import annotations

import dataclasses
import time

import numpy as np
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from soft_robot_common import (ConfigurationError, MessageGate, NodeDiagnostics, Param, declare_parameters,
                               namespaced_path, run_node)
from soft_robot_common.diagnostics import ERROR, OK, WARN
from soft_robot_common.link_state import LinkState, LinkSupervisor
from soft_robot_common.serial_link import SerialLink
from std_srvs.srv import Trigger

from ..core.marlin import GcodeSender, format_axes, parse_reply
from ..core.stepper import CableMotorMap
from .motor_params import DEFAULT_PORT_LINK, MOTOR_PARAMS

PARAMS = [
    Param("port", DEFAULT_PORT_LINK, "serial device of the Marlin board (e.g. /dev/ttyACM0); default "
          "marlin_emulator's link in this namespace: /tmp/softkin_marlin in /, /tmp/softkin_marlin_<ns> in /<ns>"),
    Param("baud", 115200, "serial baud rate", min=1200, max=4000000),
    *MOTOR_PARAMS,
    Param("min_pull", 0.0, "soft limit: smallest cable pull [m] (below it the cable is pushed slack)",
          min=-0.1, max=0.1),
    Param("max_pull", 0.0085, "soft limit: largest cable pull [m] (built-in finger: 0.85 of its two 5 mm slots)",
          min=0.0, max=0.5),
    Param("max_cable_speed", 0.01, "speed of the fastest cable in a move [m/s]", min=1e-5, max=1.0, live=True),
    Param("max_feedrate", 6000.0, "feedrate cap [axis units/min]", min=1.0, max=100000.0, live=True),
    Param("window", 1, "lines in flight without an ok", min=1, max=8),
    Param("poll_period", 0.25, "M114 polling period [s]; 0 = no polling", min=0.0, max=60.0),
    Param("settle_time", 0.3, "send M400 once no setpoint came for this long [s]; 0 = never", min=0.0, max=60.0),
    Param("banner_timeout", 3.0, "wait this long for the board's start banner after opening [s]", min=0.0,
          max=60.0),
    Param("reconnect_period", 1.0, "retry opening the port this often [s]", min=0.05, max=60.0),
    Param("ok_timeout", 10.0, "an ok not seen this long after the motion it waits for is taken as lost [s]",
          min=0.5, max=600.0),
    Param("max_queue", 500, "most commands waiting to be written; setpoints beyond are refused", min=1, max=100000),
]


#: a link state as this driver names it (Marlin's kill() is the link's emergency latch)
LINK_NAMES = {LinkState.DISCONNECTED: "disconnected", LinkState.CONNECTING: "connecting",
              LinkState.READY: "ready", LinkState.EMERGENCY: "halted"}
LINK_LEVELS = {LinkState.DISCONNECTED: ERROR, LinkState.CONNECTING: WARN,
               LinkState.READY: OK, LinkState.EMERGENCY: ERROR}
#: longest text without a line end kept from the board (more is noise)
MAX_LINE_BYTES = 4096
#: a write to the board that cannot complete within this is a lost link [s]
WRITE_TIMEOUT_S = 1.0


class StepperDriver(Node):
    NODE_NAME = "stepper_driver"

    def __init__(self):
        super().__init__(self.NODE_NAME)
        self.gate = MessageGate(self)     # non-finite, unstamped or oversized setpoints are refused
        p = self.p = declare_parameters(self, [dataclasses.replace(r, default=namespaced_path(r.default,
                                                                                        self.get_namespace()))
                                               if r.name == "port" else r for r in PARAMS],
                                        on_change=self._on_change)
        self.map = CableMotorMap(joints=list(p["joints"]), axes=list(p["axes"]), pulley_radius=p["pulley_radius"],
                                 steps_per_rev=p["steps_per_rev"], microsteps=p["microsteps"],
                                 steps_per_unit=p["steps_per_unit"], min_pull=p["min_pull"], max_pull=p["max_pull"],
                                 max_cable_speed=p["max_cable_speed"], max_feedrate=p["max_feedrate"])
        problem = self.map.problem()
        if problem:
            raise ConfigurationError(problem)
        self.sender = GcodeSender(window=p["window"])
        n = len(self.map.joints)
        self.commanded = np.zeros(n, np.int64)   # steps of the last queued move (board's plan)
        self.reported = None                     # steps the board last reported (M114 Count)
        self._stopped = False
        self._motion_until = 0.0
        self._last_move = None                   # time of the last G1 queued, until its M400
        self._last_ok = time.monotonic()
        self._last_poll = 0.0
        self._banner = False
        self._buf = b""
        self._warned_open = False
        self.stats = dict(errors=0, unknown=0, garbage=0, refused=0, moves=0, resets=0, reconnects=0, lost_oks=0)
        self.pub_state = self.create_publisher(JointState, "finger/stepper_state", 10)
        self.create_subscription(JointState, "finger/tendon_setpoints", self._on_setpoint,
                                 QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE))
        self.create_service(Trigger, "~/stop", self._srv_stop)
        self.create_service(Trigger, "~/resume", self._srv_resume)
        # the board runs in real time whatever the node clock: supervision on a steady clock
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.diagnostics = NodeDiagnostics(self, "Marlin link", self._diagnostics, hardware_id=p["port"])
        self.create_timer(0.02, self._housekeeping, clock=steady)
        # no backoff (the period is the user's), banner_timeout is the settle time, no stall check
        supervisor = LinkSupervisor(p["reconnect_period"], p["reconnect_period"], p["banner_timeout"], 0.0)
        self.link = SerialLink.for_node(self, self._on_link_events, p["port"], p["baud"], supervisor,
                                        WRITE_TIMEOUT_S)
        self.link.start()
        self.get_logger().info(f"driving {self.map.joints} on axes {self.map.axes} through {p['port']} "
                               f"({self.map.steps_per_metre:.1f} microsteps per m of cable)")

    def _on_change(self, changed: dict) -> None:
        self.map.max_cable_speed = self.p["max_cable_speed"]
        self.map.max_feedrate = self.p["max_feedrate"]

    def _link_state(self) -> LinkState:
        return self.link.snapshot().state

    # --- setpoints ----------------------------------------------------------------------
    def _refuse(self, why: str, level: str = "error") -> None:
        self.stats["refused"] += 1
        if level == "warn":    # rclpy wants one severity per call site
            self.get_logger().warn(f"setpoint refused: {why}")
        else:
            self.get_logger().error(f"setpoint refused: {why}")

    def _on_setpoint(self, msg: JointState) -> None:
        problem = self.gate.problem(msg, stamped=False)   # a zero stamp on a command means now
        if problem:
            self.stats["refused"] += 1
            self.gate.refuse("setpoint", problem)
            return
        joints = self.map.joints
        if len(msg.name) != len(msg.position) or sorted(msg.name) != sorted(joints):
            self._refuse(f"names {list(msg.name)} with {len(msg.position)} positions do not match the joints {joints}")
            return
        pulls = np.array([msg.position[list(msg.name).index(j)] for j in joints], float)
        problem = self.map.limit_problem(pulls)
        if problem:
            self._refuse(problem)
            return
        if self._stopped:
            self._refuse("the driver is stopped (call ~/resume)", "warn")
            return
        state = self._link_state()
        if state is not LinkState.READY:
            self._refuse(f"link {LINK_NAMES[state]}: not sent (nothing is replayed later)", "warn")
            return
        if self.sender.queue_depth >= self.p["max_queue"]:
            self._refuse(f"{self.sender.queue_depth} commands are waiting (max_queue)")
            return
        steps = self.map.pull_to_steps(pulls)
        values, feed, duration = self.map.move(self.commanded, steps)
        if not values:
            return     # already there to the microstep
        self.sender.enqueue(format_axes("G1", values) + f" F{feed:.2f}")
        self.commanded = steps
        now = time.monotonic()
        self._motion_until = max(now, self._motion_until) + duration
        self._last_move = now
        self.stats["moves"] += 1
        self._write_ready()

    # --- services -----------------------------------------------------------------------
    def _emergency_stop(self) -> bool:
        """Drop queued moves, M410 + M18; True if they were written to the board."""
        dropped = self.sender.abort()
        written = False
        if self._link_state() in (LinkState.READY, LinkState.EMERGENCY):
            problem = self.link.write_line((self.sender.send_unnumbered("M410") + "\n").encode("ascii"))
            if problem:
                self.get_logger().error(f"stop: writing M410 failed: {problem}")
            written = problem is None
            self.sender.enqueue("M18")
            self.sender.enqueue("M114")
        self._last_move = None
        self._motion_until = 0.0
        self.get_logger().warn(f"STOP: {dropped} queued commands dropped, M410 (quickstop) and M18 (motors off) "
                               + ("sent" if written else "not sent: no link"))
        self._write_ready()
        return written

    def _srv_stop(self, req, res):
        self._stopped = True
        written = self._emergency_stop()
        res.success = True
        res.message = "stopped: moves dropped, M410 + M18 " + ("sent" if written else "not sent (no link)")
        return res

    def _srv_resume(self, req, res):
        self._stopped = False
        if self.reported is not None:
            self.commanded = self.reported.copy()   # M410 left the plan where the motors stopped
        self.get_logger().info("resumed: setpoints are accepted again")
        res.success, res.message = True, "resumed"
        return res

    # --- the link's events (from its thread, through the executor) -----------------------
    def _on_link_events(self) -> None:
        for ev in self.link.events():
            if ev.kind == "data":
                self._on_data(ev.data)
            elif ev.kind == "opened":
                self.sender.reset()
                self._banner = False
                self._buf = b""
                self._warned_open = False
                self.get_logger().info(f"opened {self.p['port']}: waiting for the board's banner")
            elif ev.kind == "lost":
                self.sender.reset()
                self._last_move = None
                self.stats["reconnects"] += 1
                self.link.clear_emergency()     # a board that comes back has been reset
                self.get_logger().error(f"link to the board lost ({ev.text}); reconnecting, queued moves dropped")
            elif ev.kind == "open_failed" and not self._warned_open:
                self._warned_open = True
                self.get_logger().warn(f"cannot open {self.p['port']}: {ev.text}; retrying every "
                                       f"{self.p['reconnect_period']} s")
        self._write_ready()

    def _on_data(self, data: bytes) -> None:
        self._buf += data
        while b"\n" in self._buf:
            raw, self._buf = self._buf.split(b"\n", 1)
            self._handle(raw.decode("ascii", errors="replace").strip("\r\x00 "))
        if len(self._buf) > MAX_LINE_BYTES:      # no line end: noise
            self.stats["garbage"] += 1
            self._buf = b""

    def _initialise(self) -> None:
        """After the banner (or its timeout): units, absolute mode, the known position."""
        pos = self.reported if self.reported is not None else self.commanded
        self.commanded = pos.copy()
        self.sender.enqueue("G21")
        self.sender.enqueue("G90")
        self.sender.enqueue(format_axes("G92", dict(zip(self.map.axes, self.map.steps_to_axis(pos)))))
        self.sender.enqueue("M114")
        self.link.ready(time.monotonic())
        self._last_ok = time.monotonic()
        self.get_logger().info(f"board ready (banner {'seen' if self._banner else 'not seen'}); position set to "
                               f"{np.round(self.map.steps_to_pull(pos) * 1e3, 4).tolist()} mm of pull")

    def _handle(self, line: str) -> None:
        if not line:
            return
        r = parse_reply(line)
        log = self.get_logger()
        if r.kind == "ok":
            self.sender.on_ok()
            self._last_ok = time.monotonic()
        elif r.kind == "resend":
            if not self.sender.on_resend(r.line):
                log.error(f"board asked to resend line {r.line}, which is no longer known: re-synchronising")
                self.sender.abort()
            else:
                log.warn(f"board asked to resend from line {r.line}")
        elif r.kind == "position":
            try:
                self.reported = np.array([r.counts[a] for a in self.map.axes], np.int64)
            except KeyError:
                log.warn(f"position report without all axes {self.map.axes}: {line!r}")
                return
            js = JointState()
            js.header.stamp = self.get_clock().now().to_msg()
            js.name = list(self.map.joints)
            js.position = [float(v) for v in self.map.steps_to_pull(self.reported)]
            self.pub_state.publish(js)
        elif r.kind == "start":
            if self._link_state() is LinkState.CONNECTING:
                self._banner = True
            else:
                self.stats["resets"] += 1
                log.warn("the board reset (start banner mid-session): queued moves dropped, re-initialising")
                self.sender.reset()
                self._last_move = None
                self.link.clear_emergency()
                self._initialise()
        elif r.kind == "error":
            self.stats["errors"] += 1
            if any(w in line for w in ("halted", "kill() called", "stopped due to errors")):
                # Marlin's kill(): the board ignores motion until it is reset
                self.link.emergency(line)
                log.error(f"board halted ({line}): setpoints are refused until the board is reset "
                          "(reset button, power, or reconnect)")
            else:
                log.warn(f"board: {line}")
        elif r.kind == "echo":
            if "Unknown command" in line:
                self.stats["unknown"] += 1
                log.warn(f"board: {line}")
            else:
                log.debug(f"board: {line}")
        elif r.kind == "busy":
            log.debug(f"board: {line}")
        else:
            self.stats["garbage"] += 1
            log.warn(f"unrecognised line from the board ignored: {line[:80]!r}", throttle_duration_sec=2.0)

    # --- housekeeping (steady timer) -----------------------------------------------------
    def _housekeeping(self) -> None:
        now = time.monotonic()
        if self._link_state() is LinkState.CONNECTING:
            if self._banner or self.link.settled(now):
                self._initialise()
                self._write_ready()
            return
        s = self.sender
        if s.in_flight and now > max(self._last_ok, self._motion_until) + self.p["ok_timeout"]:
            self.stats["lost_oks"] += 1
            self.get_logger().warn(f"no ok for {s.in_flight_commands()[0]!r} within {self.p['ok_timeout']} s: "
                                   "taking it as lost")
            s.on_ok()
            self._last_ok = now
        settle = self.p["settle_time"]
        if settle > 0 and self._last_move is not None and now - self._last_move > settle:
            s.enqueue("M400")     # the burst (trajectory) is over: wait for the motion
            s.enqueue("M114")
            self._last_move = None
        poll = self.p["poll_period"]
        if poll > 0 and now - self._last_poll > poll and "M114" not in s.pending and \
                "M114" not in s.in_flight_commands():
            s.enqueue("M114")
            self._last_poll = now
        self._write_ready()

    def _write_ready(self) -> None:
        """Write what the ok window allows (also while halted: M18 and M114 after a stop)."""
        if self._link_state() not in (LinkState.READY, LinkState.EMERGENCY):
            return
        lines = self.sender.sendable()
        if lines:
            problem = self.link.write_line(("\n".join(lines) + "\n").encode("ascii"))
            if problem:     # the link thread reports the loss; the sender is reset then
                return
            for line in lines:
                self.get_logger().debug(f"sent {line}")

    # --- diagnostics / shutdown ---------------------------------------------------------
    def _diagnostics(self):
        link = self.link.snapshot()
        state = "stopped" if self._stopped else LINK_NAMES[link.state]
        if link.state is LinkState.EMERGENCY:
            state = f"halted ({link.emergency_text}): waiting for the board's reset"
        level = WARN if self._stopped and link.state is LinkState.READY else LINK_LEVELS[link.state]
        vals = dict(port=self.p["port"], link=state, queue_depth=self.sender.queue_depth,
                    in_flight=len(self.sender.in_flight), resends=self.sender.resends, **self.stats,
                    link_losses=link.losses, bytes_read=link.bytes_read, bytes_written=link.bytes_written)
        if link.state is LinkState.DISCONNECTED and link.last_problem:
            vals["last_problem"] = link.last_problem
        if self.reported is not None:
            vals["reported_pull_mm"] = str(np.round(self.map.steps_to_pull(self.reported) * 1e3, 4).tolist())
        vals["ready"] = link.state is LinkState.READY and not self._stopped
        return level, state, vals

    def close(self) -> None:
        """Shutdown: quick-stop and disable the motors if the link is up, then close the port.

        Runs after the executor stopped: the link's events are handled here until M18 is acknowledged.
        """
        if self._link_state() is LinkState.READY:
            self.sender.abort()
            self.link.write_line((self.sender.send_unnumbered("M410") + "\n").encode("ascii"))
            self.sender.enqueue("M18")
            end = time.monotonic() + 1.0
            while time.monotonic() < end and (self.sender.queue_depth or self.sender.in_flight):
                self._on_link_events()
                time.sleep(0.02)
            self.get_logger().info("shutdown: M410 + M18 sent")
        self.link.stop()


def main(args=None):
    return run_node(StepperDriver, args, close=lambda node: node.close())


if __name__ == "__main__":
    import sys
    sys.exit(main())
