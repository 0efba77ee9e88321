"""marlin_emulator: a Marlin board behind a pseudo-terminal, for the finger's twin and tests.

Creates a pty pair and links its device to ``port_link`` (a stable path the stepper driver
opens like the board's USB serial port); speaks the protocol of ``core.marlin_board`` with
moves that take the time their feedrate implies. Publishes ``finger/emulator/motor_state``
(JointState at ``publish_rate``: each cable's pull [m] and speed [m/s] from the motors'
*physical* positions) and ``finger/emulator/move_end`` (the same at the end of every move);
FK of those pulls is the tip the finger actually reaches.

Faults on demand (std_srvs/Trigger): ``~/reset`` (the board resets: banner, counts and line
numbers to 0, motors stay), ``~/inject_error`` (an ``Error:`` line), ``~/corrupt_next_line``
(the next numbered line fails its checksum), ``~/garbage`` (random bytes on the line),
``~/unplug`` and ``~/replug`` (the device disappears / comes back as a new pty).
"""
from __future__ import annotations

import dataclasses

import os
import select
import threading
import time

import numpy as np
from rclpy.duration import Duration
from rclpy.node import Node
from sensor_msgs.msg import JointState
from soft_robot_common import (ConfigurationError, NodeDiagnostics, Param, PathClaim, declare_parameters,
                               namespaced_path, run_node)
from soft_robot_common.pty_device import PtyDevice
from std_srvs.srv import Trigger

from ..core.marlin_board import MarlinBoard
from ..core.stepper import CableMotorMap
from .motor_params import DEFAULT_PORT_LINK, MOTOR_PARAMS

PARAMS = [
    Param("port_link", DEFAULT_PORT_LINK, "path of a symlink to the emulated board's serial device; default "
          "/tmp/softkin_marlin in the root namespace, /tmp/softkin_marlin_<ns> in /<ns>; refused if another live "
          "emulator holds it"),
    *MOTOR_PARAMS,
    Param("buffer_size", 16, "planner moves held at once (Marlin BLOCK_BUFFER_SIZE)", min=1, max=64),
    Param("publish_rate", 50.0, "rate of finger/emulator/motor_state [Hz]", min=1.0, max=500.0),
    Param("transcript", "", "file to append every received line to (with a time stamp); empty = none"),
]


class MarlinEmulator(Node):
    NODE_NAME = "marlin_emulator"

    def __init__(self):
        super().__init__(self.NODE_NAME)
        p = self.p = declare_parameters(self, [dataclasses.replace(r, default=namespaced_path(r.default,
                                                                                        self.get_namespace()))
                                               if r.name == "port_link" else r for r in PARAMS])
        self.map = CableMotorMap(joints=list(p["joints"]), axes=list(p["axes"]), pulley_radius=p["pulley_radius"],
                                 steps_per_rev=p["steps_per_rev"], microsteps=p["microsteps"],
                                 steps_per_unit=p["steps_per_unit"])
        problem = self.map.problem()
        if problem:
            raise ConfigurationError(problem)
        self.board = MarlinBoard(axes=self.map.axes, steps_per_unit=p["steps_per_unit"], buffer_size=p["buffer_size"])
        self._lock = threading.Lock()
        self.device = None
        link = p["port_link"]
        if os.path.lexists(link) and not os.path.islink(link):
            raise ConfigurationError(f"port_link {link!r} exists and is not a symbolic link; refusing to replace it")
        self._claim = PathClaim(link, "port_link")      # also: the folder must exist
        try:
            self._transcript = open(p["transcript"], "a", buffering=1) if p["transcript"] else None
        except OSError as exc:
            raise ConfigurationError(f"transcript {p['transcript']!r}: {exc.strerror}") from None
        self.device = PtyDevice(link)
        self._plug()
        self.pub_state = self.create_publisher(JointState, "finger/emulator/motor_state", 10)
        self.pub_end = self.create_publisher(JointState, "finger/emulator/move_end", 100)
        self.create_timer(1.0 / p["publish_rate"], self._publish_state)
        for name, fn in (("reset", self._reset), ("inject_error", self._inject), ("corrupt_next_line", self._corrupt),
                         ("garbage", self._garbage), ("unplug", self._unplug), ("replug", self._replug)):
            self.create_service(Trigger, f"~/{name}", fn)
        self._running = True
        self._thread = threading.Thread(target=self._serve, name="marlin_pty", daemon=True)
        self._thread.start()
        self.lines_received = 0
        self.diagnostics = NodeDiagnostics(self, "emulated board", self._diagnostics, hardware_id=p["port_link"])
        self.get_logger().info(f"emulated Marlin board on {p['port_link']} -> {self.device.device_path}")

    # --- the pty ------------------------------------------------------------------------
    def _plug(self) -> None:
        # non-blocking device: a host that does not read must not stall the motion model
        self.device.plug()
        self._buf = b""
        with self._lock:
            self.board.reset()    # a board that appears has just powered up: banner

    def _serve(self) -> None:
        while self._running:
            fd = self.device.controller
            if fd is None:
                time.sleep(0.01)
                continue
            try:
                readable = bool(select.select([fd], [], [], 0.002)[0])
                data = self.device.read() if readable else b""
            except (OSError, ValueError):    # unplugged meanwhile (~/unplug runs in the executor)
                readable, data = False, b""
            if readable and not data:        # EIO: no one has the device open
                time.sleep(0.005)
            now = time.monotonic()
            with self._lock:
                if data:
                    self._buf += data
                    while b"\n" in self._buf:
                        raw, self._buf = self._buf.split(b"\n", 1)
                        line = raw.decode("ascii", errors="replace").strip("\r")
                        if self._transcript is not None:
                            self._transcript.write(f"{now:.6f} {line}\n")
                        self.board.receive(line, now)
                        self.lines_received += 1
                self.board.tick(now)
                out = self.board.take_output()
                ends = self.board.take_completed()
            if out:
                self.device.write(("\n".join(out) + "\n").encode("ascii"))
            for t_end, steps in ends:   # stamped when the model's move ended, however late the thread woke
                self.pub_end.publish(self._state(steps, np.zeros(len(steps)), age=time.monotonic() - t_end))

    def _diagnostics(self):
        from soft_robot_common.diagnostics import OK, WARN
        plugged = self.device.plugged
        values = {"port_link": self.p["port_link"], "device": self.device.device_path if plugged else "",
                  "lines_received": self.lines_received, "dropped_bytes": self.device.dropped_bytes,
                  "ready": plugged}
        if not plugged:
            return WARN, "unplugged (fault injected): waiting for ~/replug", values
        if self.lines_received == 0:
            return OK, "waiting for G-code from the host", values
        return OK, "running", values

    # --- publishing ---------------------------------------------------------------------
    def _state(self, steps, speed, age: float = 0.0) -> JointState:
        js = JointState()
        js.header.stamp = (self.get_clock().now() - Duration(seconds=max(age, 0.0))).to_msg()
        js.name = list(self.map.joints)
        js.position = [float(v) for v in self.map.steps_to_pull(steps)]
        js.velocity = [float(v) for v in speed]
        return js

    def _publish_state(self) -> None:
        with self._lock:
            self.board.tick(time.monotonic())
            steps = self.board.physical_steps()
            speed = self.map.steps_to_pull(self.board.velocity())
        self.pub_state.publish(self._state(steps, speed))

    # --- faults -------------------------------------------------------------------------
    def _reset(self, req, res):
        with self._lock:
            self.board.reset()
        self.get_logger().warn("board reset (banner sent; counts and line numbers are 0, motors did not move)")
        res.success, res.message = True, "reset"
        return res

    def _inject(self, req, res):
        with self._lock:
            self.board.inject_error()
        res.success, res.message = True, "Error: line queued"
        return res

    def _corrupt(self, req, res):
        with self._lock:
            self.board.corrupt_next(1)
        res.success, res.message = True, "the next numbered line fails its checksum"
        return res

    def _garbage(self, req, res):
        if self.device.plugged:
            self.device.write(bytes(np.random.default_rng().integers(0, 256, 64, dtype=np.uint8)) + b"\n")
        res.success, res.message = True, "64 random bytes sent"
        return res

    def _unplug(self, req, res):
        self.device.unplug()
        self.get_logger().warn("unplugged: the device and its link are gone")
        res.success, res.message = True, "unplugged"
        return res

    def _replug(self, req, res):
        if not self.device.plugged:
            self._plug()
            self.get_logger().info(f"plugged in again as {self.device.device_path}")
        res.success, res.message = True, f"device {self.device.device_path}"
        return res

    def destroy_node(self):
        self._running = False
        if getattr(self, "_thread", None) is not None:
            self._thread.join(1.0)
        if getattr(self, "device", None) is not None:
            self.device.unplug()
        if getattr(self, "_claim", None) is not None:
            self._claim.release()
        if getattr(self, "_transcript", None) is not None:
            self._transcript.close()
        return super().destroy_node()


def main(args=None):
    return run_node(MarlinEmulator, args)


if __name__ == "__main__":
    import sys
    sys.exit(main())
