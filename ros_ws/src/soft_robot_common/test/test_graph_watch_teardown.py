"""GraphWatch.close: a middleware teardown that blocks is left behind within the bound, with where."""

import threading
import time

import pytest

from soft_robot_common import graph_watch
from soft_robot_common.graph_watch import GraphWatch


class _Context:
    def __init__(self):
        self.up = True

    def ok(self):
        return self.up


def _watch(destroy):
    """A GraphWatch on stubs (no middleware): ``destroy`` stands for the node's destroy_node."""
    w = object.__new__(GraphWatch)
    w.domain_id = 7
    w.context = _Context()
    calls = []
    w.executor = type("E", (), {"shutdown": lambda self: calls.append("executor")})()
    w.node = type("N", (), {"destroy_node": lambda self: (calls.append("node"), destroy())})()
    w._rclpy = type("R", (), {"shutdown": lambda self, context: (calls.append("rclpy"),
                                                                 setattr(context, "up", False))})()
    return w, calls


@pytest.fixture(autouse=True)
def _no_leftovers(monkeypatch):
    monkeypatch.setattr(graph_watch, "_ABANDONED", [])


def test_a_teardown_that_returns_runs_in_order_once():
    w, calls = _watch(lambda: None)
    w.close()
    w.close()
    assert calls == ["executor", "node", "rclpy"]
    assert not graph_watch.teardown_abandoned()


def test_a_blocked_teardown_is_left_behind_after_the_bound_and_says_where(monkeypatch, capsys):
    monkeypatch.setattr(graph_watch, "MIDDLEWARE_TEARDOWN_S", 0.3)
    release = threading.Event()
    w, calls = _watch(lambda: release.wait(30))
    t0 = time.monotonic()
    w.close()
    took = time.monotonic() - t0
    try:
        assert 0.3 <= took < 5.0, took
        err = capsys.readouterr().err
        assert "graph watch on domain 7: the middleware's teardown" in err and "after 0.3 s" in err
        assert "in <lambda>" in err          # the blocked thread's stack is printed
        assert graph_watch.teardown_abandoned()
        w.close()                            # a second close does not start another teardown
        assert calls == ["executor", "node"]
    finally:
        release.set()
    deadline = time.monotonic() + 10
    while graph_watch.teardown_abandoned() and time.monotonic() < deadline:
        time.sleep(0.01)
    assert not graph_watch.teardown_abandoned()       # it finished once unblocked


def test_the_exit_status_passes_through_unless_a_teardown_is_blocked(monkeypatch):
    assert graph_watch.exit_status(3) == 3
    exits = []
    monkeypatch.setattr(graph_watch.os, "_exit", exits.append)
    blocked = threading.Thread(target=threading.Event().wait, args=(5,), daemon=True)
    blocked.start()
    graph_watch._ABANDONED.append(blocked)
    graph_watch.exit_status(4)
    assert exits == [4]
