"""Supervisor: real child processes killed and restarted with back-off (no ROS)."""

import os
import signal
import time

import pytest

from soft_robot_common.processes import NodeProcess
from soft_robot_common.supervision import RestartPolicy, Supervisor, describe_exit


def _sleeper(tmp_path, label):
    return NodeProcess(["sleep", "60"], dict(os.environ), tmp_path / f"{label}.log", label)


def _poll_until(sup, predicate, timeout=10.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        sup.poll()
        if predicate():
            return
        time.sleep(0.02)
    raise TimeoutError("condition not reached")


def test_killed_node_is_restarted_after_its_backoff_and_the_backoff_doubles(tmp_path):
    sup = Supervisor(RestartPolicy(max_restarts=2, backoff_s=0.3, backoff_max_s=5.0), log=lambda s: None)
    sup.add("a", _sleeper(tmp_path, "a"), lambda label: _sleeper(tmp_path, label))
    first = sup.process("a")
    try:
        for n, backoff in ((1, 0.3), (2, 0.6)):
            t_kill = time.monotonic()
            os.kill(sup.process("a").pid, signal.SIGKILL)
            _poll_until(sup, lambda: any(e.what == "restarted" and e.detail.startswith(f"restart {n}")
                                         for e in sup.events))
            restarted = [e for e in sup.events if e.what == "restarted"][-1]
            assert restarted.time - t_kill >= backoff - 0.02
            assert sup.process("a").running() and sup.process("a").pid != first.pid
            assert sup.stop_reason is None
        assert (tmp_path / "a.2.log").exists()
        exited = [e for e in sup.events if e.what == "exited"]
        assert [describe_exit(e.code) for e in exited] == ["SIGKILL", "SIGKILL"]
        # out of restarts: the third kill ends the run, naming the node
        os.kill(sup.process("a").pid, signal.SIGKILL)
        _poll_until(sup, lambda: sup.stop_reason is not None)
        assert "a exited (SIGKILL; 2 restart(s) used)" in sup.stop_reason
        assert len(sup.processes()) == 3
    finally:
        sup.stop_all(warn=lambda s: None)
    assert not any(p.running() for p in sup.processes())


def test_essential_node_is_not_restarted(tmp_path):
    sup = Supervisor(RestartPolicy(backoff_s=0.0), essential={"world"}, log=lambda s: None)
    sup.add("world", _sleeper(tmp_path, "world"), lambda label: _sleeper(tmp_path, label))
    sup.add("other", _sleeper(tmp_path, "other"), lambda label: _sleeper(tmp_path, label))
    try:
        sup.process("world").send(signal.SIGTERM)
        _poll_until(sup, lambda: sup.stop_reason is not None)
        assert sup.stop_reason.startswith("world exited (SIGTERM; essential")
        sup.poll()
        assert len(sup.processes()) == 2 and sup.process("other").running()
    finally:
        sup.stop_all(warn=lambda s: None)


def test_policy_rejects_nonsense():
    with pytest.raises(ValueError, match="max_restarts"):
        RestartPolicy(max_restarts=-1)
    assert RestartPolicy(backoff_s=1.0, backoff_max_s=3.0).delay(5) == 3.0
