"""The liveness contracts and their monitor on a fake clock (no ROS, no processes)."""

import dataclasses
from pathlib import Path

import pytest
import yaml

from soft_robot_common.liveness import Budgets, LivenessError, LivenessMonitor, liveness_from_graph

FROG_GRAPH = Path(__file__).resolve().parents[2] / "frog_twin" / "frog_twin" / "config" / "frog_graph.yaml"
TWIN = ["recorder", "sim_node", "camera_sim", "tracker_node", "robot_emulator", "bridge_node", "planner_node"]
REAL = ["recorder", "camera_node", "tracker_node", "bridge_node", "planner_node"]


def frog(mode="sim", nodes=TWIN, **budgets):
    section = yaml.safe_load(FROG_GRAPH.read_text())["graph"]["ros__parameters"]["liveness"]
    return liveness_from_graph(section, mode, nodes, budgets)


def test_the_budgets_order_is_checked_with_reasons():
    Budgets()                                                      # the defaults hold together
    with pytest.raises(LivenessError, match="world_stall_s .* must be below restart_grace_s.*starves"):
        Budgets(world_stall_s=20.0)
    with pytest.raises(LivenessError, match="deaf_after_s .* must be below stuck_after_s"):
        Budgets(deaf_after_s=25.0)
    with pytest.raises(LivenessError, match="two diagnostics periods"):
        Budgets(deaf_after_s=1.5)
    with pytest.raises(LivenessError, match="restart_backoff_s .* must not exceed"):
        Budgets(restart_backoff_s=9.0)
    with pytest.raises(LivenessError, match="stuck_after_s = 0"):
        Budgets(stuck_after_s=0.0)
    assert Budgets(world_stall_s=0.0, deaf_after_s=0.0).problems() == []      # 0 turns a check off


def test_the_frog_graph_declares_every_edge_of_the_loop_per_mode():
    sim = frog()
    assert {e.name for e in sim.edges} == {"clock", "camera", "tracking", "decisions", "firings", "record_primitive",
                                           "record_status", "record_sent", "record_fired"}
    assert [e.producers for e in sim.edges if e.name == "camera"] == [("camera_sim",)]
    assert {r.name for r in sim.states} == {"emergency", "stuck"}
    real = frog("real", REAL)
    assert [e.producers for e in real.edges if e.name == "camera"] == [("camera_node",)]
    assert "clock" not in {e.name for e in real.edges} and "tag_lost" in {r.name for r in real.states}
    direct = frog("sim", ["recorder", "sim_node", "planner_node"])     # --no-vision --direct
    assert {e.name for e in direct.edges} == {"clock", "record_primitive", "record_status"}
    for e in sim.edges:
        assert e.carries and e.rate_hz > 0 and e.silence in {f for f in Budgets.__dataclass_fields__}


@pytest.mark.parametrize("section, message", [
    ({"edges": {"x": {"topic": "t", "producers": ["a"], "consumer": "b", "carries": "c", "rate_hz": 1.0,
                      "silence": "deaf_after_s", "then": "explode"}}}, "liveness.edges.x.then 'explode'"),
    ({"edges": {"x": {"topic": "t", "producers": ["a"], "consumer": "b", "carries": "c", "rate_hz": 1.0,
                      "silence": "forever"}}}, "'forever' is not a budget"),
    ({"edges": {"x": {"topic": "t", "colour": "red"}}}, "unknown field"),
    ({"states": {"s": {"node": "a", "key": "k", "values": ["v"], "says": "x", "clock": "moon"}}}, "clock 'moon'"),
    ({"budgets": {"deaf_after_s": -1.0}}, "deaf_after_s = -1.0"),
    ({"budgets": {"patience": 3.0}}, "patience"),
])
def test_a_bad_section_is_named(section, message):
    with pytest.raises(LivenessError, match=message):
        liveness_from_graph(section, "sim", ["a", "b"])


def test_a_world_whose_clock_stops_ends_the_run_unless_it_is_paused_on_purpose():
    m = LivenessMonitor(frog())
    t = 0.0
    while t < 5.0:
        m.message("/clock", t, t)
        assert m.evaluate(t, t) == []
        t += 0.1
    # paused by a fault for 12 s: excused, and the wait starts again after it
    for k in range(121):
        assert m.evaluate(t + k * 0.1, 5.0, held={"sim_node"}) == []
    t += 12.0
    assert m.evaluate(t + 9.9, 5.0) == []
    (v,) = m.evaluate(t + 10.0, 5.0)
    assert v.action == "stop" and v.rule == "clock" and "sim_node published nothing on /clock" in v.reason


def test_a_deaf_tracker_is_restarted_and_a_silent_camera_is_waited_for():
    m = LivenessMonitor(frog())
    for n in ("camera_sim", "tracker_node"):
        m.started(n, pid=100, now=0.0, sim=0.0)
    cam = trk = 0
    t = 0.0
    while t < 20.0:                       # both 30 Hz, reported once a second
        cam, trk = cam + 30, trk + 30 if t < 5.0 else trk
        m.message("/clock", t, t)
        m.diagnostics("camera_sim", {"frames": str(cam), "pid": "100"}, t, t)
        m.diagnostics("tracker_node", {"frames": str(trk), "pid": "100"}, t, t)
        verdicts = m.evaluate(t, t)
        if verdicts:
            break
        t += 1.0
    (v,) = verdicts
    assert v.action == "restart" and v.node == "tracker_node" and v.rule == "camera"
    assert t == pytest.approx(12.0)       # heard last at 4 s, deaf from 8 s of silence on
    assert "received nothing on camera/image_raw" in v.reason and v.since_sim == pytest.approx(4.0)
    # the camera itself silent (SIGSTOPped from outside for 5 s): wait, nothing restarted
    m2 = LivenessMonitor(frog())
    for k in range(30):
        frames = 30 * min(k, 5) + (30 * (k - 10) if k > 10 else 0)
        m2.message("/clock", float(k), float(k))
        m2.diagnostics("camera_sim", {"frames": str(frames)}, float(k), float(k))
        m2.diagnostics("tracker_node", {"frames": str(frames)}, float(k), float(k))
        assert m2.evaluate(float(k), float(k)) == []


def test_readiness_is_the_current_processes_word():
    m = LivenessMonitor(frog())
    m.started("tracker_node", pid=200, now=0.0)
    m.diagnostics("tracker_node", {"ready": "true", "pid": "199"}, 0.5)      # its predecessor's last word
    assert not m.ready("tracker_node")
    m.diagnostics("tracker_node", {"ready": "false", "pid": "200"}, 1.0)
    assert not m.ready("tracker_node")
    m.diagnostics("tracker_node", {"ready": "true", "pid": "200"}, 2.0)
    assert m.ready("tracker_node")
    m.started("recorder", pid=7, now=0.0)                # ready once subscribed to the planner's topics
    m.diagnostics("recorder", {"messages /frog/primitive": "0", "pid": "7"}, 1.0)
    assert not m.ready("recorder")
    m.diagnostics("recorder", {"messages /frog/primitive": "0", "messages /frog/planner/status": "0",
                               "pid": "7"}, 2.0)
    assert m.ready("recorder")


def test_a_planner_that_does_not_follow_stops_the_run_after_recovery_and_an_emergency_at_once():
    m = LivenessMonitor(dataclasses.replace(frog(), edges=()))        # the state rules alone
    m.value("planner_node", "status", "following", 0.0, 100.0)
    m.value("planner_node", "status", "waiting", 1.0, 101.0)
    assert m.evaluate(10.0, 110.0, down={"tracker_node"}) == []      # a node recovering: the run waits
    assert m.evaluate(11.0, 111.0) == []                             # counted from here
    assert m.evaluate(30.0, 130.9) == []
    (v,) = m.evaluate(31.0, 131.0)
    assert v.action == "stop" and "the planner has not followed (status waiting) for 20.0 s" == v.reason
    m.value("bridge_node", "state", "emergency", 32.0, 132.0)
    m.value("bridge_node", "emergency", "Central: EMERGENCY", 32.0, 132.0)
    (v,) = m.evaluate(32.0, 132.0, down={"tracker_node"})
    assert v.rule == "emergency" and "Central: EMERGENCY" in v.reason


def test_a_deaf_recorder_is_restarted_from_the_arrivals_the_monitor_saw():
    m = LivenessMonitor(frog())
    m.started("recorder", pid=5, now=0.0, sim=0.0)
    for k in range(12):
        m.message("/clock", float(k), float(k))
        m.message("/frog/primitive", float(k), float(k))                 # one decision a second
        m.diagnostics("recorder", {"messages /frog/primitive": str(min(k, 2)), "pid": "5"}, float(k), float(k))
        verdicts = [v for v in m.evaluate(float(k), float(k)) if v.rule == "record_primitive"]
        if verdicts:
            break
    (v,) = verdicts
    assert v.node == "recorder" and k == 10 and v.since_sim == pytest.approx(2.0)


def test_a_consumer_not_yet_subscribed_is_not_deaf_and_the_start_up_does_not_count():
    m = LivenessMonitor(frog())
    m.started("recorder", pid=5, now=0.0, sim=0.0)
    for k in range(20):                  # the recorder has not subscribed to frog/primitive: no key for it
        m.message("/clock", float(k), float(k))
        m.message("/frog/primitive", float(k), float(k))
        m.diagnostics("recorder", {"messages /frog/planner/status": str(k), "pid": "5"}, float(k), float(k))
        assert [v for v in m.evaluate(float(k), float(k)) if v.rule == "record_primitive"] == []
    m2 = LivenessMonitor(frog())        # silence before the run's start is forgiven by restart()
    m2.message("/clock", 0.0, 0.0)
    m2.evaluate(0.0, 0.0)
    m2.restart(9.5, 9.5)
    m2.message("/clock", 9.6, 9.6)
    assert m2.evaluate(19.0, 9.6) == [] and m2.evaluate(19.7, 9.6)[0].rule == "clock"
