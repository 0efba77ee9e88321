"""Marlin protocol, the emulated board's motion model and the cable/motor conversion (no ROS)."""
import math

import numpy as np
import pytest

from softkin_fk.core.marlin import GcodeSender, checksum, frame_line, parse_host_line, parse_reply
from softkin_fk.core.marlin_board import MarlinBoard
from softkin_fk.core.stepper import CableMotorMap


def test_checksum_matches_the_reprap_wiki_example():
    # RepRap G-code wiki: "N3 T0*57"
    assert checksum("N3 T0") == 57
    assert frame_line(3, "T0") == "N3 T0*57"
    hl = parse_host_line("N3 T0*57")
    assert (hl.number, hl.command, hl.has_checksum, hl.checksum_ok) == (3, "T0", True, True)
    assert not parse_host_line("N3 T1*57").checksum_ok


def test_reply_parsing():
    r = parse_reply("X:10.00 Y:0.50 Z:0.00 E:0.00 Count X:800 Y:40 Z:0")
    assert r.kind == "position" and r.axes == {"X": 10.0, "Y": 0.5, "Z": 0.0, "E": 0.0}
    assert r.counts == {"X": 800, "Y": 40, "Z": 0}
    assert parse_reply("Resend: 12").line == 12
    assert [parse_reply(t).kind for t in ("ok", "ok T:20", "start", "Error:checksum mismatch, Last Line: 3",
                                           'echo:Unknown command: "G999"', "\x00\xff garbage", "")] == \
        ["ok", "ok", "start", "error", "echo", "other", "other"]


def _pump(sender, board, now, lines_log=None):
    """Write what the sender may send, feed replies back; return replies seen."""
    seen = []
    for _ in range(100):
        out = sender.sendable()
        for line in out:
            if lines_log is not None:
                lines_log.append(line)
            board.receive(line, now)
        replies = board.take_output()
        seen += replies
        for r in replies:
            p = parse_reply(r)
            if p.kind == "ok":
                sender.on_ok()
            elif p.kind == "resend":
                sender.on_resend(p.line)
        if not out and not replies:
            break
    return seen


def test_sender_and_board_resend_after_checksum_errors():
    board = MarlinBoard()
    board.take_output()   # banner
    s = GcodeSender(window=1)
    cmds = ["G21", "G90", "G92 X0 Y0 Z0", "M114", "G1 X1.0000 F600", "M114"]
    for c in cmds:
        s.enqueue(c)
    board.corrupt_next(3)   # three lines lost to noise, the first of them M110
    sent = []
    replies = _pump(s, board, 0.0, sent)
    assert sum(r.startswith("Resend:") for r in replies) == 3 and s.resends == 3
    # every command arrives exactly once and in order (the garbled M110 is not needed: the
    # board asks for line 1, which is in sync), line numbers consecutive
    assert board.received == cmds
    numbers = [parse_host_line(line).number for line in sent]
    assert numbers[0] == 0 and sorted(set(numbers)) == list(range(len(cmds) + 1))
    assert board.last_n == len(cmds)
    assert s.queue_depth == 0 and not s.in_flight


def test_board_refuses_wrong_line_numbers_and_missing_checksums():
    b = MarlinBoard()
    b.take_output()
    b.receive(frame_line(0, "M110 N0"), 0.0)
    b.receive(frame_line(5, "G21"), 0.0)
    b.receive("N1 G21", 0.0)
    out = b.take_output()
    assert out == ["ok", "Error:Line Number is not Last Line Number+1, Last Line: 0", "Resend: 1",
                   "Error:No Checksum with line number, Last Line: 0", "Resend: 1"]
    b.receive("G999", 0.0)
    assert b.take_output() == ['echo:Unknown command: "G999"', "ok"]


def test_board_motion_takes_the_feedrate_time_and_m400_waits():
    b = MarlinBoard(steps_per_unit=80.0)
    b.take_output()
    b.receive("G1 X10 Y0 F600", 0.0)       # 10 units at 600 units/min: 1.0 s
    b.receive("M400", 0.0)
    assert b.take_output() == ["ok"]       # the move is queued; M400 waits
    b.tick(0.5)
    assert b.counts.tolist() == [400, 0, 0] and b.take_output() == []
    b.receive("M114", 0.5)                 # behind M400: not answered yet
    assert b.take_output() == []
    b.tick(1.0)
    out = b.take_output()
    assert out[0] == "ok" and parse_reply(out[1]).counts == {"X": 800, "Y": 0, "Z": 0} and out[2] == "ok"
    # diagonal: both axes arrive together, length sqrt(3^2 + 4^2) = 5 units at F300: 1 s
    b.receive("G1 X13 Y4 F300", 2.0)
    b.tick(2.5)
    assert b.counts.tolist() == [920, 160, 0]
    assert b.velocity().tolist() == pytest.approx([240.0, 320.0, 0.0])   # steps/s: (3, 4) units/s x 80
    b.tick(3.0)
    assert b.counts.tolist() == [1040, 320, 0]
    done = b.take_completed()
    assert [p.tolist() for _, p in done] == [[800, 0, 0], [1040, 320, 0]]
    assert [t for t, _ in done] == pytest.approx([1.0, 3.0])     # the model's own end times


def test_board_reset_quickstop_and_g92_keep_the_physical_position():
    b = MarlinBoard()
    b.receive("G1 X10 F600", 0.0)
    b.tick(0.25)                           # a quarter of the way: 200 steps
    b.receive("M410", 0.25)
    b.tick(5.0)
    assert b.physical_steps().tolist() == [200, 0, 0] and not b.busy()
    b.reset()
    assert b.take_output()[-4] == "start" and b.counts.tolist() == [0, 0, 0]
    assert b.physical_steps().tolist() == [200, 0, 0]          # the motor did not move
    b.receive("G92 X2.5", 5.0)                                 # host restores the known position
    assert b.counts.tolist() == [200, 0, 0]
    b.receive("G1 X0 F600", 5.0)
    b.tick(10.0)
    assert b.physical_steps().tolist() == [0, 0, 0]
    b.receive("M18", 10.0)
    assert not b.enabled


def test_cable_motor_map_conversion_limits_and_synchronised_feedrate():
    m = CableMotorMap(pulley_radius=0.005, steps_per_rev=200, microsteps=16, steps_per_unit=80.0,
                      max_cable_speed=0.01)
    assert m.problem() is None
    one_turn = 2 * math.pi * 0.005
    assert m.pull_to_steps([one_turn, 0.0, one_turn / 2]).tolist() == [3200, 0, 1600]
    assert m.steps_to_pull(m.pull_to_steps([0.003, 0.001, 0.0])) == pytest.approx([0.003, 0.001, 0.0], abs=1e-5)
    assert "below min_pull" in m.limit_problem([-1e-4, 0, 0])
    assert "exceeds max_pull" in m.limit_problem([0, 0.009, 0])
    assert "not finite" in m.limit_problem([0, math.nan, 0])
    assert m.limit_problem([0.0, 0.0085, 0.004]) is None
    a, b = np.array([0, 0, 0]), m.pull_to_steps([0.002, 0.001, 0.0005])
    values, feed, duration = m.move(a, b)
    d_units = np.linalg.norm((b - a) / 80.0)
    # Marlin covers the axis-space length at F units/min: it takes `duration`, and the
    # fastest cable (2 mm) moves at the speed limit
    assert feed / 60.0 * duration == pytest.approx(d_units, rel=1e-12)
    assert m.steps_to_pull(b[0]) / duration == pytest.approx(0.01, rel=1e-12)
    assert values == {"X": b[0] / 80.0, "Y": b[1] / 80.0, "Z": b[2] / 80.0}
    assert m.move(b, b) == ({}, 0.0, 0.0)
    assert "same, non-zero length" in CableMotorMap(axes=["X", "Y"]).problem()


def test_sender_window_keeps_taken_lines_in_flight_on_resend():
    s = GcodeSender(window=3)
    for c in ("G21", "G90", "M114", "M400"):
        s.enqueue(c)
    assert s.sendable() == [frame_line(0, "M110 N0"), frame_line(1, "G21"), frame_line(2, "G90")]
    assert s.on_ok() == "M110 N0"
    assert s.sendable() == [frame_line(3, "M114")]
    # line 2 was garbled; 1 was taken (its ok is still to come), 2 and 3 go again
    assert s.on_resend(2) and list(s.in_flight) == [1]
    assert s.sendable() == [frame_line(2, "G90"), frame_line(3, "M114")]
    assert [s.on_ok() for _ in range(3)] == ["G21", "G90", "M114"]
    assert s.sendable() == [frame_line(4, "M400")]
    assert not s.on_resend(99)      # a line never sent cannot be resent


def test_a_resend_for_the_numbering_before_a_reset_keeps_the_queue():
    """A poll written just before the board reset is answered after the host has reset its
    numbering ('Resend: 1' from the fresh board): the re-initialisation queued must survive."""
    s = GcodeSender(window=1)
    s.enqueue("M114")
    assert s.sendable() == [frame_line(0, "M110 N0")]
    s.on_ok()
    assert s.sendable() == [frame_line(1, "M114")]       # in flight when the board resets
    s.reset()                                             # the host sees the start banner
    for c in ("G21", "G90", "G92 X2.5500 Y1.2750 Z0.0000", "M114"):
        s.enqueue(c)
    assert s.on_resend(1)                                 # the fresh board's answer to N1
    assert s.queue_depth == 5 and s.resends == 0
    assert s.sendable() == [frame_line(0, "M110 N0")]
    for n, c in enumerate(("G21", "G90", "G92 X2.5500 Y1.2750 Z0.0000", "M114"), start=1):
        s.on_ok()
        assert s.sendable() == [frame_line(n, c)]
