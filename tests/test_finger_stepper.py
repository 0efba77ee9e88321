"""stepper_driver against a scripted board on a pty (exact G-code) and against marlin_emulator.

The expected lines are computed here from the hardware numbers (pulley radius 5 mm, 200
steps/rev, 16 microsteps, 80 microsteps per axis unit, fastest cable at 10 mm/s) and the
RepRap checksum rule, independently of the driver's code.
"""

import math
import os
import select
import time

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

pytestmark = pytest.mark.system

QOS = QoSProfile(depth=200, reliability=ReliabilityPolicy.RELIABLE)
JOINTS = ["cable_0", "cable_1", "cable_2"]
STEPS_PER_M = 200 * 16 / (2 * math.pi * 0.005)


def cs(body):
    c = 0
    for ch in body.encode():
        c ^= ch
    return f"{body}*{c}"


def line(n, cmd):
    return cs(f"N{n} {cmd}")


def g1(prev_pull, pull, speed=0.01):
    """The G1 the hardware numbers call for (absolute axis units, synchronising feedrate)."""
    a = np.rint(np.array(prev_pull) * STEPS_PER_M)
    b = np.rint(np.array(pull) * STEPS_PER_M)
    duration = np.abs(b - a).max() / STEPS_PER_M / speed
    feed = 60 * np.linalg.norm((b - a) / 80.0) / duration
    return "G1 " + " ".join(f"{ax}{v / 80.0:.4f}" for ax, v in zip("XYZ", b)) + f" F{feed:.2f}"


class Board:
    """The test's end of the pty: read the driver's lines, write replies."""

    def __init__(self, fd):
        self.fd, self.buf = fd, b""

    def write(self, *lines):
        os.write(self.fd, ("\n".join(lines) + "\n").encode())

    def read(self, timeout=5.0):
        end = time.monotonic() + timeout
        while b"\n" not in self.buf:
            left = end - time.monotonic()
            if left <= 0:
                return None
            r, _, _ = select.select([self.fd], [], [], left)
            if r:
                self.buf += os.read(self.fd, 4096)
        raw, self.buf = self.buf.split(b"\n", 1)
        return raw.decode()

    def expect(self, expected, ok=True, timeout=5.0):
        got = self.read(timeout)
        assert got == expected, f"driver sent {got!r}, expected {expected!r}"
        if ok:
            self.write("ok")


def _js(names, pos):
    return JointState(name=list(names), position=[float(v) for v in pos])


def _heard_from(probe, node):
    """Wait for ``node``'s diagnostics (1 Hz): it has then matched the probe's earlier subscriptions."""
    probe.wait_heard(DiagnosticArray, "/diagnostics", timeout=30,
                     accept=lambda m: any(st.name.startswith(f"{node}:") for st in m.status))


def _start(launch, probe, path, **params):
    drv = launch("stepper_driver", params=dict(dict(port=path, poll_period=0.0, settle_time=0.5,
                                                    banner_timeout=10.0), **params))
    drv.wait_for_log("waiting for the board's banner", timeout=30)
    pub = probe.node.create_publisher(JointState, "/finger/tendon_setpoints", QOS)
    probe.wait_matched(pub, timeout=30)
    return drv, pub


def _handshake(board):
    board.write("start", "echo:Marlin 2.1.2")
    board.expect(line(0, "M110 N0"))
    board.expect(line(1, "G21"))
    board.expect(line(2, "G90"))
    board.expect(line(3, "G92 X0.0000 Y0.0000 Z0.0000"))
    board.expect(line(4, "M114"), ok=False)
    board.write("X:0.00 Y:0.00 Z:0.00 E:0.00 Count X:0 Y:0 Z:0", "ok")


def test_exact_gcode_resend_soft_limits_and_stop(launch, probe, serial_pair):
    fd, path = serial_pair
    drv, pub = _start(launch, probe, path)
    board = Board(fd)
    states = []
    probe.node.create_subscription(JointState, "/finger/stepper_state", states.append, QOS)
    _heard_from(probe, "stepper_driver")    # its stepper_state now reaches the probe
    _handshake(board)
    probe.spin_until(lambda: states, 10, "stepper_state")
    assert list(states[-1].name) == JOINTS and list(states[-1].position) == [0.0, 0.0, 0.0]

    p1, p2 = [0.002, 0.001, 0.0005], [0.003, 0.001, 0.0]
    pub.publish(_js(JOINTS, p1))
    board.expect(line(5, g1([0, 0, 0], p1)))
    pub.publish(_js(["cable_2", "cable_0", "cable_1"], [p2[2], p2[0], p2[1]]))   # matched by name
    board.expect(line(6, g1(p1, p2)))
    # the burst is over: M400 (wait for the motion), then where the motors are
    board.expect(line(7, "M400"), timeout=3)
    board.expect(line(8, "M114"), ok=False)
    counts = np.rint(np.array(p2) * STEPS_PER_M).astype(int)
    board.write(f"X:0.00 Y:0.00 Z:0.00 E:0.00 Count X:{counts[0]} Y:{counts[1]} Z:{counts[2]}", "ok")
    probe.spin_until(lambda: len(states) >= 2, 10, "second stepper_state")
    assert np.allclose(states[-1].position, counts / STEPS_PER_M, atol=1e-12)

    # refused whole, nothing sent: soft limits, wrong names/lengths, NaN
    for names, pos, why in ((JOINTS, [0.009, 0, 0], "exceeds max_pull"),
                            (JOINTS, [0.001, -0.0001, 0], "below min_pull"),
                            (["cable_0", "cable_1", "cable_9"], [0, 0, 0], "do not match the joints"),
                            (JOINTS[:2], [0.001, 0.001], "do not match the joints"),
                            (JOINTS, [0.001, math.nan, 0], "not finite")):
        pub.publish(_js(names, pos))
        drv.wait_for_log(why, timeout=5)
    js = JointState(name=JOINTS, position=[0.001, 0.001])   # name/position lengths differ
    pub.publish(js)
    drv.wait_for_log(r"names \['cable_0', 'cable_1', 'cable_2'\] with 2 positions", timeout=5)
    # nothing was sent for any of them: the next line the board reads is the next setpoint's, N9

    # a checksum error: the same line is sent again
    p3 = [0.004, 0.002, 0.001]
    pub.publish(_js(JOINTS, p3))
    board.expect(line(9, g1(p2, p3)), ok=False)
    board.write("Error:checksum mismatch, Last Line: 8", "Resend: 9")
    board.expect(line(9, g1(p2, p3)))
    board.expect(line(10, "M400"), timeout=3)
    board.expect(line(11, "M114"), ok=False)
    board.write(f"X:0.00 Y:0.00 Z:0.00 E:0.00 Count X:{counts[0]} Y:{counts[1]} Z:{counts[2]}", "ok")

    # garbage and unknown-command echoes are logged; nothing is sent for them
    os.write(fd, bytes(range(1, 250, 3)) + b"\n")
    board.write('echo:Unknown command: "G999"', "Error:Printer halted. kill() called!")
    drv.wait_for_log("unrecognised line from the board", timeout=5)
    drv.wait_for_log("Unknown command", timeout=5)
    drv.wait_for_log("Printer halted", timeout=5)

    # emergency stop: M410 at once (unnumbered, ahead of any queue), numbering re-synced, M18
    stop = probe.node.create_client(Trigger, "/stepper_driver/stop")
    probe.wait_for_service(stop)
    res = probe.call(stop, Trigger.Request())
    assert res.success and "sent" in res.message
    assert board.read(3) == "M410"
    board.write("ok")
    board.expect(line(12, "M110 N12"))
    board.expect(line(13, "M18"))
    board.expect(line(14, "M114"), ok=False)
    board.write(f"X:0.00 Y:0.00 Z:0.00 E:0.00 Count X:{counts[0]} Y:{counts[1]} Z:{counts[2]}", "ok")
    pub.publish(_js(JOINTS, p1))
    drv.wait_for_log("the driver is stopped", timeout=5)
    # the refused p1 was never sent: the next lines on the wire are the re-initialisation after
    # the (halted) board's reset, and after ~/resume the next setpoint's G1 from where the motors
    # were reported (a p1 sent late would come first, or the G1 would start from p1)
    board.write("start")
    drv.wait_for_log("the board reset", timeout=5)
    board.expect(line(0, "M110 N0"))
    board.expect(line(1, "G21"))
    board.expect(line(2, "G90"))
    board.expect(line(3, "G92 " + " ".join(f"{ax}{v / 80.0:.4f}" for ax, v in zip("XYZ", counts))))
    board.expect(line(4, "M114"), ok=False)
    board.write(f"X:0.00 Y:0.00 Z:0.00 E:0.00 Count X:{counts[0]} Y:{counts[1]} Z:{counts[2]}", "ok")
    assert probe.call(probe.node.create_client(Trigger, "/stepper_driver/resume"), Trigger.Request()).success
    pub.publish(_js(JOINTS, p3))
    board.expect(line(5, g1(p2, p3)))
    assert drv.running()
    assert drv.stop() == 0 and drv.stopped_cleanly


def test_a_lost_ok_is_given_up_after_ok_timeout(launch, probe, serial_pair):
    fd, path = serial_pair
    drv, pub = _start(launch, probe, path, ok_timeout=0.5)
    board = Board(fd)
    _handshake(board)
    p1, p2 = [0.001, 0.0, 0.0], [0.002, 0.0, 0.0]
    pub.publish(_js(JOINTS, p1))
    board.expect(line(5, g1([0, 0, 0], p1)), ok=False)     # the ok is lost on the wire
    pub.publish(_js(JOINTS, p2))
    drv.wait_for_log("within 0.5 s: taking it as lost", timeout=10)
    board.expect(line(6, g1(p1, p2)))
    assert drv.stop() == 0 and drv.stopped_cleanly


def test_board_vanishing_is_logged_and_nothing_is_replayed(launch, probe, serial_pair, tmp_path):
    fd, path = serial_pair
    drv, pub = _start(launch, probe, path, reconnect_period=0.2)
    board = Board(fd)
    _handshake(board)
    p1 = [0.001, 0.0, 0.0]
    pub.publish(_js(JOINTS, p1))
    board.expect(line(5, g1([0, 0, 0], p1)))
    diags = []
    probe.node.create_subscription(DiagnosticArray, "/diagnostics", diags.append, 10)
    os.close(fd)   # the board is unplugged
    drv.wait_for_log("link to the board lost", timeout=10)
    pub.publish(_js(JOINTS, [0.002, 0.0, 0.0]))
    drv.wait_for_log(r"setpoint refused: link disconnected", timeout=10)
    # it stays up while the port is gone: two more diagnostics updates (1 s apart) say so
    n = len(diags)
    probe.spin_until(lambda: len(diags) >= n + 2, 30, "two diagnostics updates while disconnected")
    assert drv.running()
    st = diags[-1].status[0]
    assert st.level == st.ERROR and st.message == "disconnected"
    assert drv.stop() == 0 and drv.stopped_cleanly


def _emulated(launch, probe, tmp_path, **driver):
    link = str(tmp_path / "marlin")
    transcript = tmp_path / "transcript.txt"
    emu = launch("marlin_emulator", params=dict(port_link=link, transcript=str(transcript)))
    emu.wait_for_log("emulated Marlin board", timeout=30)
    drv = launch("stepper_driver", params=dict(dict(port=link, banner_timeout=0.3, poll_period=0.2,
                                                    settle_time=0.3, reconnect_period=0.2), **driver))
    drv.wait_for_log("board ready", timeout=30)
    pub = probe.node.create_publisher(JointState, "/finger/tendon_setpoints", QOS)
    probe.wait_matched(pub, timeout=30)
    for topic in ("/finger/emulator/move_end", "/finger/stepper_state"):
        probe.wait_for_topic(topic, timeout=20)
    return emu, drv, pub, transcript


def _settle(probe):
    """Both nodes have matched the probe's subscriptions (made before) before anything is published."""
    _heard_from(probe, "marlin_emulator")
    _heard_from(probe, "stepper_driver")


def _lines(transcript):
    return [ln.split(" ", 1)[1] for ln in transcript.read_text().splitlines()]


def test_driver_moves_the_emulated_board_in_the_feedrate_time(launch, probe, tmp_path):
    # no polling: the line corrupted below must be the G1, not an M114 poll
    emu, drv, pub, transcript = _emulated(launch, probe, tmp_path, poll_period=0.0)
    ends, states, motor = [], [], []
    probe.node.create_subscription(JointState, "/finger/emulator/move_end", ends.append, QOS)
    probe.node.create_subscription(JointState, "/finger/stepper_state", states.append, QOS)
    probe.node.create_subscription(JointState, "/finger/emulator/motor_state", motor.append, QOS)
    _settle(probe)
    targets = [[0.0004 * k, 0.0002 * k, 0.0001 * k] for k in range(1, 11)]
    # the fastest cable moves 0.4 mm per step at 10 mm/s: 40 ms per move, 0.4 s for the ramp
    for p in targets:
        pub.publish(_js(JOINTS, p))
        probe.spin_for(0.01)
    probe.spin_until(lambda: len(ends) >= 10, 20, "10 completed moves")
    q = np.rint(np.array(targets) * STEPS_PER_M) / STEPS_PER_M
    got = np.array([m.position for m in ends[:10]])
    assert np.allclose(got, q, atol=1e-12), (got, q)    # each move ends on the quantised setpoint
    t = np.array([m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for m in ends[:10]])
    assert np.median(np.diff(t)) == pytest.approx(0.04, abs=0.005), np.diff(t)    # the model's own end times
    # after M400 the driver's report equals the emulator's physical position
    probe.spin_until(lambda: states and np.allclose(states[-1].position, q[-1], atol=1e-12), 10, "final report")
    assert any(" M400*" in ln for ln in _lines(transcript))
    assert max(abs(v) for m in motor for v in m.velocity) == pytest.approx(0.01, rel=0.01)   # cable speed limit

    # a corrupted line is resent and executed once
    r = probe.call(probe.node.create_client(Trigger, "/marlin_emulator/corrupt_next_line"), Trigger.Request())
    assert r.success
    pub.publish(_js(JOINTS, [0.001, 0.001, 0.001]))
    probe.spin_until(lambda: len(ends) >= 11, 10, "move after a resend")
    drv.wait_for_log("resend from line", timeout=5)
    assert np.allclose(ends[-1].position, np.rint(np.full(3, 0.001) * STEPS_PER_M) / STEPS_PER_M, atol=1e-12)
    g1s = [ln for ln in _lines(transcript) if " G1 " in ln]
    assert len(g1s) == len(set(g1s)) + 1, g1s     # exactly one line arrived twice (the resent one)


def test_board_reset_and_replug_recover_without_replaying(launch, probe, tmp_path):
    emu, drv, pub, transcript = _emulated(launch, probe, tmp_path)
    ends, states = [], []
    probe.node.create_subscription(JointState, "/finger/emulator/move_end", ends.append, QOS)
    probe.node.create_subscription(JointState, "/finger/stepper_state", states.append, QOS)
    _settle(probe)
    p = [0.002, 0.001, 0.0]
    q = np.rint(np.array(p) * STEPS_PER_M) / STEPS_PER_M
    pub.publish(_js(JOINTS, p))
    probe.spin_until(lambda: ends, 10, "first move")
    # M400 + M114: the driver knows where the motors are (its report is the move's end)
    probe.spin_until(lambda: states and np.allclose(states[-1].position, q, atol=1e-12), 15, "report of the move")
    reset = probe.node.create_client(Trigger, "/marlin_emulator/reset")
    assert probe.call(reset, Trigger.Request()).success
    drv.wait_for_log("the board reset", timeout=10)
    drv.wait_for_log(r"board ready.*position set to \[2\.0", timeout=10)

    def since(marker):       # the transcript's lines since the last line containing marker
        lines = _lines(transcript)
        return lines[max(i for i, ln in enumerate(lines) if marker in ln):]

    def m114s(lines):
        return sum(" M114*" in ln for ln in lines)
    # the re-initialisation (the second M110 N0), its M114 and a later poll (every 0.2 s) reached
    # the board: past any replay
    probe.spin_until(lambda: sum(" M110 N0*" in ln for ln in _lines(transcript)) >= 2
                     and m114s(since("M110 N0")) >= 2, 15, "two M114 since the re-initialisation")
    after = since("M110 N0")
    g92 = "G92 " + " ".join(f"{ax}{v / 80:.4f}" for ax, v in zip("XYZ", np.rint(np.array(p) * STEPS_PER_M)))
    assert any(g92 in ln for ln in after), (g92, after)
    assert not any(" G1 " in ln for ln in after), "a move was replayed after the reset"
    # unplugged: refused while gone, no replay after the replug
    assert probe.call(probe.node.create_client(Trigger, "/marlin_emulator/unplug"), Trigger.Request()).success
    drv.wait_for_log("link to the board lost", timeout=10)
    pub.publish(_js(JOINTS, [0.003, 0.001, 0.0]))
    drv.wait_for_log("setpoint refused: link", timeout=10)
    n_before = len(_lines(transcript))
    assert probe.call(probe.node.create_client(Trigger, "/marlin_emulator/replug"), Trigger.Request()).success
    probe.spin_until(lambda: drv.log_text().count("board ready") >= 3, 15, "reconnect")
    probe.spin_until(lambda: m114s(_lines(transcript)[n_before:]) >= 2, 15, "two M114 since the replug")
    assert not any(" G1 " in ln for ln in _lines(transcript)[n_before:]), "a refused setpoint was sent later"
    pub.publish(_js(JOINTS, [0.003, 0.001, 0.0]))
    probe.spin_until(lambda: len(ends) >= 2, 10, "move after the replug")
    assert np.allclose(ends[-1].position, np.rint(np.array([0.003, 0.001, 0.0]) * STEPS_PER_M) / STEPS_PER_M,
                       atol=1e-12)
    assert emu.running() and drv.running()


def test_bad_configuration_exits_2_with_the_reason(launch, tmp_path):
    # (not "Y": YAML 1.1 reads an unquoted Y on the command line as a boolean)
    cases = [("stepper_driver", dict(axes=["X", "Z"]), "same, non-zero length"),
             ("stepper_driver", dict(min_pull=0.01, max_pull=0.005), "min_pull"),
             ("marlin_emulator", dict(axes=["X", "X", "Z"], port_link=str(tmp_path / "m")), "distinct"),
             ("kinematics_node", dict(mesh_file=str(tmp_path / "missing.msh")), "needs both mesh_file and spec_file"),
             ("kinematics_node", dict(marker="knuckle"), "no marker 'knuckle'")]
    for exe, params, why in cases:
        p = launch(exe, params=params)
        assert p.wait(60) == 2, p.log_text()
        assert why in p.log_text(), p.log_text()
