"""Supervisor: real child processes killed and restarted with back-off (no ROS)."""

import os
import signal
import sys
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
    bad_exit = "import signal, sys, time; signal.signal(signal.SIGINT, lambda *a: sys.exit(3)); time.sleep(60)"
    sup.add("other", NodeProcess([sys.executable, "-c", bad_exit], dict(os.environ), tmp_path / "other.log", "other"),
            lambda label: _sleeper(tmp_path, label))
    try:
        sup.process("world").send(signal.SIGTERM)
        _poll_until(sup, lambda: sup.stop_reason is not None)
        assert sup.stop_reason.startswith("world exited (SIGTERM; essential")
        sup.poll()
        assert len(sup.processes()) == 2 and sup.process("other").running()
    finally:
        sup.stop_all(warn=lambda s: None)
    assert sup.unclean_stops() == ["other"], "exit 3 on SIGINT is unclean; the world's exit is the stop reason"


def test_a_node_waiting_for_its_restart_at_the_stop_is_not_an_unclean_stop(tmp_path):
    """Session 31: a recorder killed as deaf 2 s before the goal, its restart due in 4 s, made the run
    'failed' for an unclean stop; its process had ended before the stop, and the event says why."""
    sup = Supervisor(RestartPolicy(backoff_s=30.0, backoff_max_s=30.0), log=lambda s: None)
    sup.add("rec", _sleeper(tmp_path, "rec"), lambda label: _sleeper(tmp_path, label))
    sup.add("bad", _sleeper(tmp_path, "bad"), lambda label: _sleeper(tmp_path, label))
    try:
        sup.kill_hung("rec", "deaf")
        os.kill(sup.process("bad").pid, signal.SIGKILL)
        _poll_until(sup, lambda: sum(e.what == "exited" for e in sup.events) == 2)
        assert sup.recovering() == ["rec", "bad"] and sup.stop_reason is None
    finally:
        sup.stop_all(warn=lambda s: None)
    assert sup.unclean_stops() == []
    assert len(sup.processes()) == 2, "no restart at the stop"
    # (a process that ends badly at the stop is still unclean: test_essential_node_is_not_restarted)


def test_policy_rejects_nonsense():
    with pytest.raises(ValueError, match="max_restarts"):
        RestartPolicy(max_restarts=-1)
    assert RestartPolicy(backoff_s=1.0, backoff_max_s=3.0).delay(5) == 3.0


def _ready(folder, process) -> bool:
    """The test processes' typed readiness: a file named after the process."""
    return (folder / f"{process.name}.ready").exists()


def test_a_node_that_never_gets_ready_is_killed_and_restarted(tmp_path):
    """A restarted process that never says it is ready counts as hung: SIGKILL,
    then the normal restart; a restart that does get ready is left alone past the timeout.
    The first start is not checked (the caller waits for it)."""
    starts = []

    def start(label):       # the first restart hangs, the second works (it writes its ready file)
        cmd = "exec sleep 60" if not starts else f"touch {tmp_path / label}.ready; exec sleep 60"
        starts.append(label)
        return NodeProcess(["sh", "-c", cmd], dict(os.environ), tmp_path / f"{label}.log", label)
    sup = Supervisor(RestartPolicy(max_restarts=2, backoff_s=0.0), log=lambda s: None)
    sup.add("tracker", _sleeper(tmp_path, "tracker"), start, ready=lambda p: _ready(tmp_path, p), ready_timeout_s=0.5)
    try:
        end = time.monotonic() + 1.0          # the first start: never checked
        while time.monotonic() < end:
            sup.poll()
            time.sleep(0.05)
        assert sup.events == [] and sup.process("tracker").running()
        sup.process("tracker").send(signal.SIGKILL)
        _poll_until(sup, lambda: any(e.what == "restarted" for e in sup.events))
        first = sup.process("tracker")
        _poll_until(sup, lambda: sum(e.what == "restarted" for e in sup.events) == 2)
        hung = [e for e in sup.events if e.what == "hung"]
        assert len(hung) == 1 and "within 0.5 s" in hung[0].detail
        assert hung[0].time - first.started_at >= 0.5
        assert describe_exit(first.proc.returncode) == "SIGKILL"
        end = time.monotonic() + 1.5          # three timeouts: the ready restart keeps running
        while time.monotonic() < end:
            sup.poll()
            time.sleep(0.05)
        assert sup.process("tracker").running() and sup.stop_reason is None
        assert [e.what for e in sup.events] == ["exited", "restarted", "hung", "exited", "restarted"]
    finally:
        sup.stop_all(warn=lambda s: None)


def test_a_node_out_of_restarts_that_hangs_ends_the_run(tmp_path):
    sup = Supervisor(RestartPolicy(max_restarts=1, backoff_s=0.0), log=lambda s: None)
    sup.add("tracker", _sleeper(tmp_path, "tracker"), lambda label: _sleeper(tmp_path, label),
            ready=lambda p: False, ready_timeout_s=0.3)
    try:
        sup.process("tracker").send(signal.SIGKILL)
        _poll_until(sup, lambda: sup.stop_reason is not None)
        assert sup.stop_reason.startswith("tracker exited (SIGKILL; 1 restart(s) used)")
        with pytest.raises(ValueError, match="ready_timeout_s"):
            sup.add("x", sup.process("tracker"), lambda label: None, ready=lambda p: True, ready_timeout_s=0)
    finally:
        sup.stop_all(warn=lambda s: None)
    assert sup.unclean_stops() == [], "its exit is the stop reason, not an unclean stop at the end"


def test_a_node_is_recovering_from_its_exit_until_its_restart_is_ready(tmp_path):
    starts = []

    def start(label):       # the first restart hangs, the second gets ready
        cmd = "exec sleep 60" if not starts else f"sleep 0.3; touch {tmp_path / label}.ready; exec sleep 60"
        starts.append(label)
        return NodeProcess(["sh", "-c", cmd], dict(os.environ), tmp_path / f"{label}.log", label)
    sup = Supervisor(RestartPolicy(max_restarts=2, backoff_s=0.3), log=lambda s: None)
    sup.add("tracker", _sleeper(tmp_path, "tracker"), start, ready=lambda p: _ready(tmp_path, p), ready_timeout_s=0.6)
    sup.add("planner", _sleeper(tmp_path, "planner"), lambda label: _sleeper(tmp_path, label))
    seen = [sup.recovering()]
    try:
        sup.process("tracker").send(signal.SIGKILL)
        sup.process("planner").send(signal.SIGKILL)
        # both gone before the supervisor looks (under load one can die a poll later than the other)
        for name in ("tracker", "planner"):
            sup.process(name).wait(timeout=20.0)
        end = time.monotonic() + 20.0
        while time.monotonic() < end and not (len(starts) == 2 and sup.recovering() == []):
            sup.poll()
            state = sorted(sup.recovering())
            if seen[-1] != state:
                seen.append(state)
            time.sleep(0.02)
        # both wait for their restarts; the planner (no readiness check) is back once restarted,
        # the tracker once a restart of it says it is ready (the first one hangs and is restarted)
        assert seen == [[], ["planner", "tracker"], ["tracker"], []], seen
        assert [e.what for e in sup.events if e.node == "tracker"] == ["exited", "restarted", "hung", "exited",
                                                                       "restarted"]
        sup.process("tracker").send(signal.SIGKILL)        # out of restarts: given up, not recovering
        _poll_until(sup, lambda: sup.stop_reason is not None)
        assert sup.recovering() == []
    finally:
        sup.stop_all(warn=lambda s: None)


def test_a_running_node_found_hung_by_the_caller_is_killed_and_restarted(tmp_path):
    sup = Supervisor(RestartPolicy(max_restarts=1, backoff_s=0.1), log=lambda s: None)
    sup.add("tracker", _sleeper(tmp_path, "tracker"), lambda label: _sleeper(tmp_path, label))
    first = sup.process("tracker")
    try:
        sup.kill_hung("tracker", "deaf for 8.0 s")
        assert not first.running() and first.proc.returncode == -signal.SIGKILL
        _poll_until(sup, lambda: any(e.what == "restarted" for e in sup.events))
        assert [e.what for e in sup.events] == ["hung", "exited", "restarted"]
        assert sup.events[0].detail == "deaf for 8.0 s; SIGKILL"
        assert sup.process("tracker").running() and sup.stop_reason is None
        sup.kill_hung("tracker", "deaf again")          # out of restarts: the run stops, naming it
        _poll_until(sup, lambda: sup.stop_reason is not None)
        assert sup.stop_reason.startswith("tracker exited (SIGKILL; 1 restart(s) used)")
    finally:
        sup.stop_all(warn=lambda s: None)


def test_a_slow_but_clean_stop_is_mentioned_and_stays_clean(tmp_path):
    slow = ("import signal, sys, time\n"
            "def bye(*a):\n    time.sleep(3.5)\n    sys.exit(0)\n"
            "signal.signal(signal.SIGINT, bye)\nprint('up', flush=True)\ntime.sleep(60)\n")
    sup = Supervisor(RestartPolicy(), log=lambda s: None)
    sup.add("cam", NodeProcess([sys.executable, "-c", slow], dict(os.environ), tmp_path / "cam.log", "cam"),
            lambda label: _sleeper(tmp_path, label))
    sup.process("cam").wait_for_log("up")
    said = []
    sup.stop_all(warn=said.append)
    assert sup.unclean_stops() == []
    report = sup.summary()["stops"]["cam"]
    assert report["signal"] == "SIGINT" and report["code"] == 0 and 3.5 <= report["seconds"] < 10, report
    assert len(said) == 1 and said[0].startswith("  note: cam took") and "s to stop; log" in said[0], said
