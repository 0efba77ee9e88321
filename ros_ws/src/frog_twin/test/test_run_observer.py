"""The twin's watch (RunObserver): when the recorder counts as up for the recording check.

Seen in a series of runs: a SIGSTOPped recorder was killed for deaf and restarted; the restarted one met
the restarted-reader wedge (subscribed to /frog/bridge/sent, receiving nothing, never subscribed to the
planner's topics), and while the supervisor waited 15 s for it to get ready the check counted it up, so
7 messages it never received were "lost while up" and the run failed.
"""

import pytest

pytest.importorskip("soft_robot_interfaces.msg")

from frog_twin.core.faults import recorder_losses  # noqa: E402
from frog_twin.fault_injection import RunObserver  # noqa: E402

TOPIC = "/frog/bridge/sent"


class _Node:
    """What RunObserver needs of a node here: it subscribes; no messages flow in this test."""

    def create_subscription(self, *args, **kwargs):
        return None


def _at(obs, t, recorder_running=True, ready=True):
    obs.sim_now = t
    obs.watch_recorder(recorder_running, ready=ready)


def _run(unready_counts_as_up: bool):
    obs = RunObserver(_Node())
    recorded = {t: [] for t in obs.seen}

    def publish(t, got):
        obs.seen[TOPIC].append(t)
        if got:
            recorded[TOPIC].append(t)

    for k in range(100, 141):                  # the first recorder: up, records everything
        _at(obs, k / 10)
        publish(k / 10 + 0.05, got=True)
    _at(obs, 14.1, recorder_running=False)     # killed
    obs.sim_now = 15.0
    obs.node_restarted("recorder")
    for k in range(150, 300):                  # restarted, wedged: the graph shows subscriptions, not ready
        _at(obs, k / 10, ready=unready_counts_as_up)
        publish(k / 10 + 0.05, got=False)
    _at(obs, 30.0, recorder_running=False)     # killed as hung (never ready)
    obs.sim_now = 31.0
    obs.node_restarted("recorder")
    _at(obs, 31.2, ready=False)
    for k in range(315, 360):                  # ready: up again, records everything
        _at(obs, k / 10)
        publish(k / 10 + 0.05, got=True)
    obs.close_recorder_interval(True)
    return obs, recorded


def test_a_restarted_recorder_is_not_up_before_it_is_ready_and_its_unready_time_is_said():
    obs, recorded = _run(unready_counts_as_up=False)
    losses = recorder_losses(obs.seen, recorded, obs.recorder_up)
    assert losses[TOPIC]["lost"] == 0 and losses[TOPIC]["expected"] > 40, losses
    assert obs.recorder_unready == [(15.0, 31.0)], obs.recorder_unready
    missed = recorder_losses(obs.seen, recorded, obs.recorder_unready, margin=0.0)[TOPIC]["lost"]
    assert missed == 150, missed               # every message published while it was not ready
    # up: the first recorder, then the second restart from its readiness; never while unready
    assert [(round(a, 1), round(b, 1)) for a, b in obs.recorder_up] == [(10.0, 14.1), (31.5, 35.9)]


def test_counting_the_unready_recorder_as_up_would_lose_what_it_never_received():
    """The same run with readiness ignored (the rule before): the check fails the run."""
    obs, recorded = _run(unready_counts_as_up=True)
    assert recorder_losses(obs.seen, recorded, obs.recorder_up)[TOPIC]["lost"] > 100
