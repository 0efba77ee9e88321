"""``robot_emulator``: the nRF52 relay and the frog robot behind a pseudo-terminal.

Creates a pty pair and links its device to ``link_path`` (or opens ``device``), parses the
``p``/``h`` lines the bridge writes like the robot firmware, delays each line by the BLE
model (:mod:`frog_bridge.core.emulator`) and publishes what the robot fired on
``frog/limb_activation`` (LimbActivation, stamped on the node clock: simulated time when
the graph runs on ``/clock``), which ``sim_node`` executes. It writes ``Central: Q w x y z``
lines from the heading in ``frog/sim/odom`` at ``imu_rate_hz``, and injects faults on
request: ``~/inject_emergency``, ``~/unplug`` (and ``~/replug``; back after the live
``unplug_duration_s``, 0 = only on ``~/replug``), ``~/inject_garbage``, ``~/stall``
(std_srvs/Trigger), and BLE loss bursts through the live ``loss_rate``.
"""

from __future__ import annotations

import csv
import dataclasses
import math
import os
import queue
import select
import sys
import threading
import time
from collections import deque

import numpy as np
from nav_msgs.msg import Odometry
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from soft_robot_common import (ConfigurationError, MessageGate, NodeDiagnostics, Param, PathClaim,
                               declare_parameters, namespaced_path, run_node)
from std_srvs.srv import Trigger

from frog_bridge.core.emulator import (
    DEFAULT_BLE_INTERVAL_S, DEFAULT_BLE_LATENCY_S, BleLinkModel, Fire, RobotFirmware)
from frog_common.primitives import limb_label
from frog_bridge.core.protocol import (
    QUATERNION_ORDERS, DecodeError, LineFramer, SetPulse, encode_emergency, encode_quaternion, excerpt)
from soft_robot_common.pty_device import OpenedDevice, PtyDevice
from frog_common.se2 import quaternion_yaw, yaw_quaternion

PARAMS = [
    Param("link_path", "/tmp/frog_robot_tty", "stable path linked to the emulated device (the bridge's port); "
          "default /tmp/frog_robot_tty in the root namespace, /tmp/frog_robot_tty_<ns> in /<ns>; refused if "
          "another live emulator holds it"),
    Param("device", "", "open this existing serial device instead of creating a pty (link_path unused)"),
    Param("ble_latency_s", DEFAULT_BLE_LATENCY_S, "fixed relay + BLE + firmware delay per line [s]",
          min=0.0, max=1.0),
    Param("ble_interval_s", DEFAULT_BLE_INTERVAL_S, "BLE connection interval: uniform extra delay in [0, it) [s]",
          min=0.0, max=1.0),
    Param("loss_rate", 0.0, "probability that a line is lost over BLE; live (a loss burst: set it, then back)",
          min=0.0, max=1.0, live=True),
    Param("seed", -1, "random seed of the BLE model and garbage; -1 = random", min=-1),
    Param("initial_pulse_ms", 80, "firmware pulse length until a 'p' line arrives [ms]", min=1, max=1000),
    Param("imu_rate_hz", 20.0, "rate of 'Central: Q' lines [Hz]; 0 = none", min=0.0, max=500.0),
    Param("quaternion_order", "wxyz", "order of the numbers in 'Central: Q' lines", choices=QUATERNION_ORDERS),
    Param("command_log", "", "CSV file of every line received (wall time, line, what the robot did); empty = none"),
    Param("unplug_duration_s", 1.0, "~/unplug plugs back in after this [s]; 0 = stay unplugged until ~/replug",
          min=0.0, max=3600.0, live=True),
    Param("stall_duration_s", 2.0, "~/stall stops reading and writing for this long [s]", min=0.0, max=3600.0,
          live=True),
    Param("garbage_lines", 200, "lines written by ~/inject_garbage", min=1, max=100_000, live=True),
]


class RobotEmulator(Node):
    """Emulated relay + robot; parameters in :data:`PARAMS`."""

    NODE_NAME = "robot_emulator"

    def __init__(self, **kwargs):
        super().__init__("robot_emulator", **kwargs)
        p = declare_parameters(self, [dataclasses.replace(r, default=namespaced_path(r.default, self.get_namespace()))
                                      if r.name == "link_path" else r for r in PARAMS], on_change=self._on_parameters)
        self.cfg = p
        from soft_robot_interfaces.msg import LimbActivation
        self._LimbActivation = LimbActivation
        link = p["link_path"]
        if p["device"]:
            if not os.path.exists(p["device"]):
                raise ConfigurationError(f"device {p['device']!r} does not exist")
        elif os.path.lexists(link) and not os.path.islink(link):
            raise ConfigurationError(f"link_path {link!r} exists and is not a symbolic link; refusing to replace it")
        elif not os.path.isdir(os.path.dirname(os.path.abspath(link))):
            raise ConfigurationError(f"link_path {link!r}: folder does not exist")
        self._claim = None if p["device"] else PathClaim(link, "link_path")
        seed = None if p["seed"] < 0 else p["seed"]
        self.rng = np.random.default_rng(seed)
        # the fault writer's own stream (a Generator is not shared between threads)
        self._garbage_rng = np.random.default_rng(None if seed is None else [seed, 1])
        self.ble = BleLinkModel(p["ble_latency_s"], p["ble_interval_s"], p["loss_rate"], self.rng)
        self.firmware = RobotFirmware(p["initial_pulse_ms"])
        self.framer = LineFramer(4096)
        self.device = OpenedDevice(p["device"]) if p["device"] else PtyDevice(link)
        self.yaw: float | None = None
        self.stalled_until = 0.0
        self.counts = {"lines": 0, "fired": 0, "lost": 0, "errors": 0}
        self._log_file = None
        self._log = None
        if p["command_log"]:
            try:
                self._log_file = open(p["command_log"], "w", newline="", buffering=1)
            except OSError as exc:
                raise ConfigurationError(f"command_log {p['command_log']!r}: {exc.strerror}") from exc
            self._log = csv.writer(self._log_file)
            self._log.writerow(["wall_time_s", "line", "result"])
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._fire_timers = []

        qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        self.fired_pub = self.create_publisher(LimbActivation, "frog/limb_activation", qos)
        self.gate = MessageGate(self)    # non-finite or oversized odometry is refused
        self.create_subscription(Odometry, "frog/sim/odom", self.on_odom, qos)
        for name, cb in (("inject_emergency", self.on_emergency), ("unplug", self.on_unplug),
                         ("replug", self.on_replug), ("inject_garbage", self.on_garbage), ("stall", self.on_stall)):
            self.create_service(Trigger, f"~/{name}", cb)
        if p["imu_rate_hz"] > 0:
            self.create_timer(1.0 / p["imu_rate_hz"], self.write_imu, clock=self._steady)
        # rclpy's wait only returns to Python (where SIGINT is handled) when something is ready:
        # without any timer the node could not be stopped.
        self.create_timer(0.2, lambda: None, clock=self._steady)

        # The reader thread owns plugging/unplugging (so it never reads a closed descriptor);
        # other threads ask through ``_requests`` and the wake pipe.
        self._events: deque = deque()
        self._requests: deque = deque()
        self._wake_r, self._wake_w = os.pipe()
        self._wake = self.create_guard_condition(self.on_lines)
        self._running = True
        try:
            path = self.device.plug()
        except OSError as exc:
            raise ConfigurationError(f"cannot open the emulated device: {exc}") from exc
        self._thread = threading.Thread(target=self._reader, name="pty_reader", daemon=True)
        self._thread.start()
        # Faults that write a lot (garbage) wait for the reader of the pty: never inside an
        # executor callback, where they would block services, parameters and shutdown.
        self._faults: queue.Queue = queue.Queue()
        self._fault_thread = threading.Thread(target=self._fault_worker, name="fault_writer", daemon=True)
        self._fault_thread.start()
        self.diagnostics = NodeDiagnostics(self, "emulated relay", self._diagnostics,
                                           hardware_id=p["device"] or link)
        where = path if p["device"] else f"{link} -> {path}"
        self.get_logger().info(f"emulated relay on {where}; BLE {p['ble_latency_s'] * 1e3:g} ms + "
                               f"U(0, {p['ble_interval_s'] * 1e3:g}) ms, loss {p['loss_rate']:g}, IMU "
                               f"{p['imu_rate_hz']:g} Hz")

    def _on_parameters(self, changed: dict) -> None:
        if "loss_rate" in changed:          # read by the executor thread only (_deliver), as set here
            self.ble.loss_rate = float(changed["loss_rate"])

    def _diagnostics(self):
        from soft_robot_common.diagnostics import OK, WARN
        values = dict(self.counts, device=self.device.device_path, dropped_bytes=self.device.dropped_bytes,
                      heading_known=self.yaw is not None, loss_rate=self.ble.loss_rate, ready=self.device.plugged)
        if not self.device.plugged:
            return WARN, "unplugged (fault injected): waiting for ~/replug or the replug timer", values
        if time.monotonic() < self.stalled_until:
            return WARN, "stalled (fault injected)", values
        if self.counts["lines"] == 0:
            return OK, "waiting for lines from the bridge", values
        return OK, "relaying", values

    # -- reader thread ----------------------------------------------------------------------
    def _request(self, what: str, arg=None) -> None:
        self._requests.append((what, arg))
        os.write(self._wake_w, b"x")

    def _reader(self) -> None:
        while self._running:
            while self._requests:
                what, arg = self._requests.popleft()
                if what == "unplug":
                    self.device.unplug()
                    self.framer.reset()
                elif what == "plug":
                    self.device.plug()
                self._events.append(("device", time.time(), what))
                self._wake.trigger()
            fds = [self._wake_r]
            if self.device.plugged and time.monotonic() >= self.stalled_until:
                fds.append(self.device.controller)
            timeout = 0.05 if len(fds) == 1 else 0.5
            ready, _, _ = select.select(fds, [], [], timeout)
            if self._wake_r in ready:
                os.read(self._wake_r, 4096)
            if len(fds) > 1 and fds[1] in ready:
                data = self.device.read()
                t = time.time()
                if not data:
                    time.sleep(0.01)      # EIO: nobody has the device open yet
                    continue
                for item in self.framer.feed(data):
                    self._events.append(("line", t, item))
                self._wake.trigger()

    # -- executor side ------------------------------------------------------------------------
    def on_lines(self) -> None:
        while self._events:
            kind, t, item = self._events.popleft()
            if kind == "device":
                self._record(t, b"", f"device {item}ged")
                self.get_logger().info(f"device {item}ged" + (f": {self.cfg['link_path']} -> "
                                                                f"{self.device.device_path}" if item == "plug" else ""))
                continue
            self.counts["lines"] += 1
            if isinstance(item, DecodeError):
                self._record(t, b"", f"error: {item}")
                continue
            result = self.firmware.handle(item)
            if isinstance(result, DecodeError):
                self.counts["errors"] += 1
                self.get_logger().warn(f"firmware: bad line {result}")
                self._record(t, item, f"error: {result.kind.value}")
            elif isinstance(result, SetPulse):
                self.get_logger().info(f"firmware: pulse length {result.ms} ms")
                self._record(t, item, f"pulse {result.ms} ms")
            elif isinstance(result, Fire):
                self._deliver(t, item, result)
            else:
                self._record(t, item, "blank")

    def _record(self, t: float, line: bytes, result: str) -> None:
        if self._log is not None:
            self._log.writerow([f"{t:.6f}", line.decode("utf-8", "backslashreplace").rstrip("\r"), result])

    def _deliver(self, t_rx: float, line: bytes, fire: Fire) -> None:
        # the BLE model works in the reader's wall time; the delay is real time (steady clock)
        t_fire = self.ble.delivery_time(t_rx)
        if t_fire is None:
            self.counts["lost"] += 1
            self.get_logger().warn(f"line {excerpt(line)} lost over BLE")
            self._record(t_rx, line, "lost over BLE")
            return
        self._record(t_rx, line, f"fire {limb_label(fire.limbs)} at +{(t_fire - t_rx) * 1e3:.1f} ms")
        delay = t_fire - time.time()
        timer = None

        def fire_now():
            self.destroy_timer(timer)
            self._fire_timers.remove(timer)
            self._fire(fire)
        timer = self.create_timer(max(delay, 1e-4), fire_now, clock=self._steady)
        self._fire_timers.append(timer)

    def _fire(self, fire: Fire) -> None:
        msg = self._LimbActivation(limbs=list(fire.limbs), pulse_duration=fire.pulse_s)
        msg.header.stamp = self.get_clock().now().to_msg()
        self.fired_pub.publish(msg)
        self.counts["fired"] += 1
        self.get_logger().debug(f"fired {limb_label(fire.limbs)} for {fire.pulse_s * 1e3:g} ms")

    def on_odom(self, msg: Odometry) -> None:
        problem = self.gate.problem(msg, stamped=False)    # only the heading is used: any stamp will do
        if problem:
            self.counts["odom_refused"] = self.counts.get("odom_refused", 0) + 1
            if self.gate.should_log("frog/sim/odom", problem):    # once a second per problem
                self.get_logger().warn(f"frog/sim/odom refused: {problem}; the IMU keeps the last good heading")
            return
        o = msg.pose.pose.orientation
        yaw = quaternion_yaw(o.w, o.x, o.y, o.z)
        if self.yaw is None:
            self.get_logger().info(f"odometry received: heading {math.degrees(yaw):.1f} deg")
        self.yaw = yaw

    def write_imu(self) -> None:
        if self.yaw is None or time.monotonic() < self.stalled_until:
            return
        x, y, z, w = yaw_quaternion(self.yaw)
        self.device.write(encode_quaternion(w, x, y, z, order=self.cfg["quaternion_order"]))

    # -- faults -------------------------------------------------------------------------------
    def on_emergency(self, request, response):
        n = self.device.write(encode_emergency())
        self._record(time.time(), b"", "fault: wrote Central: EMERGENCY")
        self.get_logger().warn("fault: wrote 'Central: EMERGENCY'")
        response.success, response.message = n > 0, "EMERGENCY written" if n else "device unplugged"
        return response

    def on_unplug(self, request, response):
        self._record(time.time(), b"", "fault: unplugged")
        self._request("unplug")
        after = self.cfg["unplug_duration_s"]
        if after > 0:
            timer = None

            def replug():
                self.destroy_timer(timer)
                self._request("plug")
            timer = self.create_timer(after, replug, clock=self._steady)
        self.get_logger().warn(f"fault: unplugged{f', replug in {after:g} s' if after else ''}")
        response.success, response.message = True, "unplugged"
        return response

    def on_replug(self, request, response):
        self._request("plug")
        response.success, response.message = True, "plugged"
        return response

    def on_stall(self, request, response):
        self.stalled_until = time.monotonic() + self.cfg["stall_duration_s"]
        self.get_logger().warn(f"fault: link stalled for {self.cfg['stall_duration_s']:g} s")
        response.success, response.message = True, "stalled"
        return response

    def on_garbage(self, request, response):
        n = self.cfg["garbage_lines"]
        if not self._faults.empty():
            response.success, response.message = False, "garbage injection already under way"
            return response
        self._faults.put(n)
        self.get_logger().warn(f"fault: writing {n} garbage lines (in the background)")
        response.success, response.message = True, f"writing {n} garbage lines"
        return response

    # seconds a garbage line may wait for the reader; the first line that cannot be written
    # within it ends the injection (nobody reads the device)
    GARBAGE_WRITE_TIMEOUT_S = 2.0

    def _fault_worker(self) -> None:
        while self._running:
            try:
                n = self._faults.get(timeout=0.2)
            except queue.Empty:
                continue
            written = lines = 0
            for i in range(n):
                if not self._running:
                    break
                line = garbage_line(self._garbage_rng, i)
                done = self.device.write_all(line, timeout=self.GARBAGE_WRITE_TIMEOUT_S)
                written += done
                if done < len(line):
                    break
                lines += 1
            self._faults.task_done()
            note = "" if lines == n else f" of {n} (the device is not being read; the rest dropped)"
            self.get_logger().warn(f"fault: wrote {lines} garbage lines{note} ({written} bytes)")

    def close(self) -> None:
        self._running = False
        os.write(self._wake_w, b"x")
        self._thread.join(2.0)
        self._fault_thread.join(2.0)
        self.device.unplug()
        if self._claim is not None:
            self._claim.release()
        if self._log_file is not None:
            self._log_file.close()
        self.get_logger().info(f"emulator stopped: {self.counts}")


def garbage_line(rng: np.random.Generator, i: int) -> bytes:
    """One bad line: binary, non-UTF-8, 10 kB long, a bad quaternion, or a partial line."""
    kind = i % 5
    if kind == 0:
        return rng.integers(0, 256, int(rng.integers(1, 120)), dtype=np.uint8).tobytes().replace(b"\n", b"") + b"\n"
    if kind == 1:
        return b"Central: Q \xff\xfe\xc3\x28 0 0\r\n"
    if kind == 2:
        return b"Central: " + b"X" * 10_000 + b"\r\n"
    if kind == 3:
        return b"Central: Q 1 nan 0 0 7\r\n"
    return b"Central: Q 0.7071 0.0"          # partial: the next line completes (and spoils) it


def main(args=None) -> int:
    return run_node(RobotEmulator, args, close=lambda node: node.close())


if __name__ == "__main__":
    sys.exit(main())
