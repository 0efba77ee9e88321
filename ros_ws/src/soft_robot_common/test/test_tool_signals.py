"""A tool's stop signals and a started node's stop when its tool dies (real processes, no ROS graph)."""

import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest

from soft_robot_common.processes import NodeProcess
from soft_robot_common.tool_signals import rclpy_call, stop_on_signals

# a node's stand-in: stop_with_parent as run_node calls it, and a SIGTERM handler that says so
CHILD = textwrap.dedent("""
    import signal, sys, time
    from soft_robot_common.node_main import stop_with_parent
    signal.signal(signal.SIGTERM, lambda *_: (print("SIGTERM", flush=True), sys.exit(0)))
    stop_with_parent()
    print("started", flush=True)
    time.sleep(60)
""")

# a tool's stand-in: starts the child with NodeProcess, prints its pid, waits
TOOL = textwrap.dedent("""
    import os, sys, time
    from pathlib import Path
    from soft_robot_common.processes import NodeProcess
    p = NodeProcess([sys.executable, "-c", sys.argv[1]], dict(os.environ), Path(sys.argv[2]), "child")
    p.wait_for_log("started", 20)
    print(p.pid, flush=True)
    time.sleep(60)
""")


def _gone(pid, timeout):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return True
        time.sleep(0.05)
    return False


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="prctl(PR_SET_PDEATHSIG) is Linux's")
@pytest.mark.system
def test_a_node_gets_sigterm_when_the_tool_that_started_it_is_killed(tmp_path):
    log = tmp_path / "child.log"
    tool = subprocess.Popen([sys.executable, "-c", TOOL, CHILD, str(log)], stdout=subprocess.PIPE, text=True)
    try:
        child = int(tool.stdout.readline())
        os.kill(tool.pid, signal.SIGKILL)
        tool.wait(10)
        # the child is reaped by init, so 'gone' means it exited
        assert _gone(child, 10), "the child outlived its tool's SIGKILL"
        assert "SIGTERM" in log.read_text()
    finally:
        tool.kill()


@pytest.mark.system
def test_a_node_started_without_its_parent_alive_stops_at_once(tmp_path):
    # with its parent (this test) alive, the child runs on
    p = NodeProcess([sys.executable, "-c", CHILD], dict(os.environ), tmp_path / "c.log", "child")
    try:
        p.wait_for_log("started", 20)
        time.sleep(0.5)
        assert p.running()
    finally:
        p.stop()
    # the environment names a parent that is already gone (it died before the prctl)
    gone = subprocess.Popen(["true"])
    gone.wait()
    orphan = subprocess.Popen([sys.executable, "-c", CHILD],
                              env=dict(os.environ, SOFT_ROBOT_PARENT_PID=str(gone.pid)),
                              stdout=subprocess.PIPE, text=True)
    assert orphan.wait(10) == 0
    assert orphan.stdout.read().startswith("SIGTERM")


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
@pytest.mark.system
def test_sigterm_and_sighup_stop_a_tool_like_ctrl_c(sig):
    tool = textwrap.dedent("""
        import time
        from soft_robot_common.tool_signals import stop_on_signals
        stop_on_signals()
        try:
            print("ready", flush=True)
            time.sleep(30)
        except KeyboardInterrupt as exc:
            print("stopped by", exc.args[0], flush=True)
        finally:
            print("cleaned up", flush=True)
    """)
    p = subprocess.Popen([sys.executable, "-c", tool], stdout=subprocess.PIPE, text=True)
    assert p.stdout.readline().strip() == "ready"
    p.send_signal(sig)
    assert p.wait(10) == 0
    assert p.stdout.read().split("\n")[:2] == [f"stopped by {signal.Signals(sig).name}", "cleaned up"]


def test_a_stop_inside_an_rclpy_call_is_raised_when_the_call_returns():
    previous = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}
    restore = stop_on_signals()
    reached = []
    try:
        with pytest.raises(KeyboardInterrupt, match="SIGTERM"):
            with rclpy_call():
                os.kill(os.getpid(), signal.SIGTERM)
                time.sleep(0.1)          # the handler has run here: it must not raise inside
                reached.append(True)
        assert reached == [True]
        with pytest.raises(KeyboardInterrupt, match="Ctrl-C"):      # outside one: at once
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(1)
    finally:
        restore()
    assert {s: signal.getsignal(s) for s in previous} == previous
