"""SerialLink against a real pty (PtyDevice): read, write, unplug, reconnect (no ROS)."""

import os
import select
import threading
import time

import pytest

from soft_robot_common.link_state import LinkState, LinkSupervisor
from soft_robot_common.pty_device import OpenedDevice, PtyDevice
from soft_robot_common.serial_link import SerialLink


def wait_for(pred, timeout=5.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return True
        time.sleep(0.01)
    return pred()


def read_device(dev, timeout=2.0):
    end = time.monotonic() + timeout
    got = b""
    while time.monotonic() < end and not got.endswith(b"\n"):
        if select.select([dev.controller], [], [], 0.05)[0]:
            got += dev.read()
    return got


@pytest.fixture
def device(tmp_path):
    dev = PtyDevice(str(tmp_path / "tty"))
    dev.plug()
    yield dev
    dev.unplug()


def test_read_write_unplug_replug(device):
    events, woken = [], threading.Event()
    sup = LinkSupervisor(reconnect_period_s=0.1, reconnect_max_period_s=0.2, settle_s=0.0)
    link = SerialLink(device.link_path, 115200, sup, woken.set)
    link.start()
    try:
        def collect():
            events.extend(link.events())
            return events
        assert wait_for(lambda: any(e.kind == "opened" for e in collect()))
        assert sup.state is LinkState.CONNECTING
        sup.ready(time.monotonic())
        assert link.write_line(b"h 1 0\n") is None
        assert read_device(device) == b"h 1 0\n"
        device.write(b"Central: Q 1 0 0 0\r\n")
        assert wait_for(lambda: b"".join(e.data for e in collect()) == b"Central: Q 1 0 0 0\r\n")

        device.unplug()
        assert wait_for(lambda: any(e.kind == "lost" for e in collect()))
        assert sup.state is LinkState.DISCONNECTED
        assert link.write_line(b"h 1\n") == "port is not open"
        events.clear()
        assert wait_for(lambda: any(e.kind == "open_failed" for e in collect()))   # retries fail: no such file
        device.write(b"stale\n")                      # dropped: unplugged devices take nothing
        device.plug()
        assert wait_for(lambda: any(e.kind == "opened" for e in collect()), 1.0)
        sup.ready(time.monotonic())
        assert link.write_line(b"h 2 3\n") is None
        assert read_device(device) == b"h 2 3\n"
        assert not any(e.kind == "data" and b"stale" in e.data for e in collect())
    finally:
        link.stop()


def test_write_to_a_stuck_reader_times_out_and_loses_the_link(device):
    sup = LinkSupervisor(reconnect_period_s=5.0, reconnect_max_period_s=5.0, settle_s=0.0)
    link = SerialLink(device.link_path, 115200, sup, lambda: None, write_timeout_s=0.05)
    link.start()
    try:
        assert wait_for(lambda: sup.connection is LinkState.CONNECTING)
        # nobody reads the controller side: the pty buffer fills and a write times out
        problem = None
        for _ in range(10_000):
            problem = link.write_line(b"h 1 0\n" * 100)
            if problem:
                break
        assert problem and "write" in problem
        assert wait_for(lambda: sup.connection is LinkState.DISCONNECTED)
    finally:
        link.stop()


def test_opened_device_mode():
    controller, dev_fd = os.openpty()
    try:
        dev = OpenedDevice(os.ttyname(dev_fd))
        dev.plug()
        dev.write(b"Central: EMERGENCY\r\n")
        assert os.read(controller, 100) == b"Central: EMERGENCY\r\n"
        dev.unplug()
        assert not dev.plugged and dev.write(b"x") == 0
    finally:
        os.close(controller)
        os.close(dev_fd)


def test_snapshot_follows_the_line_the_latch_and_the_loss(device):
    """What nodes read through snapshot(): lines, stall, the emergency latch above the connection, losses."""
    sup = LinkSupervisor(reconnect_period_s=0.1, reconnect_max_period_s=0.2, settle_s=0.05, stall_timeout_s=0.2)
    link = SerialLink(device.link_path, 115200, sup, lambda: None)
    link.start()
    try:
        assert wait_for(lambda: link.connecting_since() is not None)
        opened = link.connecting_since()
        assert not link.settled(opened + 0.01) and link.settled(opened + 0.06)
        link.ready(opened + 0.06)
        snap = link.snapshot(opened + 0.1)
        assert snap.state is LinkState.READY and snap.line_age is None and not snap.stalled
        assert link.snapshot(opened + 0.3).stalled          # READY and silent for longer than 0.2 s
        link.line_received(opened + 0.3)
        snap = link.snapshot(opened + 0.4)
        assert snap.line_age == pytest.approx(0.1) and not snap.stalled
        assert link.emergency("Central: EMERGENCY") and not link.emergency("again")   # latched once
        snap = link.snapshot()
        assert snap.state is LinkState.EMERGENCY and snap.emergency_text == "again"
        assert link.write_line(b"h 1 0\n") is None          # the latch is the node's to honour
        assert read_device(device) == b"h 1 0\n"
        assert link.snapshot().bytes_written == 6
        assert link.clear_emergency() and not link.clear_emergency()
        assert link.snapshot().state is LinkState.READY
        device.unplug()
        assert wait_for(lambda: link.snapshot().state is LinkState.DISCONNECTED)
        snap = link.snapshot()
        assert snap.losses == 1 and ("read failed" in snap.last_problem or "closed" in snap.last_problem)
    finally:
        link.stop()
