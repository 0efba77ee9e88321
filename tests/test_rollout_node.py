"""rollout_node as a real process: the simulator's transitions of a search tree over DDS.

Truth: the same rollouts run in this process through frog_sim's core (itself tested against
FrogSimulation.step in frog_sim/test/test_rollouts.py). The wire layout is checked by
chaining the returned rows with the planner's own eq. 18 (frog_planner.core.prediction):
level 1 then level 2 must land on the world poses the core computed for each pair.
"""

import itertools
import math

import numpy as np
import pytest

pytestmark = pytest.mark.system

PERIOD = 1.0
POSE = (0.10, 0.20, 0.30)
TWIST = (0.02, 0.0, 0.1)


def _request(depth, fired=(("FL", 0.3),), pose=POSE, twist=TWIST, period=PERIOD, lead=0.0, first=()):
    from geometry_msgs.msg import Pose2D, Twist
    from soft_robot_interfaces.srv import Rollouts
    t = Twist()
    t.linear.x, t.linear.y, t.angular.z = twist
    return Rollouts.Request(pose=Pose2D(x=pose[0], y=pose[1], theta=pose[2]), twist=t,
                            fired_limbs=[f for f, _ in fired], fired_ago=[a for _, a in fired],
                            period=period, depth=depth, lead=lead, first_primitives=list(first))


def test_depth_two_tree_over_the_wire_chains_to_the_cores_poses(launch, probe):
    from soft_robot_interfaces.srv import Rollouts

    from frog_planner.core.prediction import apply_transition
    from frog_sim.core.rollouts import Rollouts as CoreRollouts
    node = launch("rollout_node", params={"threads": 1})
    node.wait_for_log("ready in", timeout=240)
    client = probe.node.create_client(Rollouts, "/frog/rollouts")
    probe.wait_for_service(client, timeout=30)
    res = probe.call(client, _request(2), timeout=120)
    assert res.success, res.message
    names = list(res.primitive_names)
    assert names == list("ABCDEFGHI")
    rows = np.asarray(res.transitions).reshape(-1, 6)
    assert rows.shape == (9 + 81, 6) and res.compute_time > 0

    with CoreRollouts(threads=1) as core:
        start = core.estimated_start(POSE, TWIST, {"FL": -0.3}, now=0.0)
        pairs = list(itertools.product(names, repeat=2))
        truth = core.rollout_batch(start, pairs, period=PERIOD)
    level1, level2 = rows[:9], rows[9:]
    first_pose, first_vel = apply_transition(np.array(POSE), level1)                  # (9, 3)
    second_pose, _ = apply_transition(np.repeat(first_pose, 9, axis=0), level2)      # (81, 3)
    # two processes' Newton solves stop at the force tolerance, so they agree to ~1e-8, not
    # bit for bit; a wrong layout (frame, order) is off by centimetres and tenths of radians
    np.testing.assert_allclose(first_vel, truth.transitions[::9, 0, 3:], atol=1e-7)
    np.testing.assert_allclose(first_pose[:, :2], truth.pose[::9, 0, :2], atol=1e-7)
    np.testing.assert_allclose(second_pose[:, :2], truth.pose[:, 1, :2], atol=1e-7)
    dyaw = np.angle(np.exp(1j * (second_pose[:, 2] - truth.pose[:, 1, 2])))
    assert np.max(np.abs(dyaw)) < 1e-6
    # B (all four limbs) goes further forward than I (nothing fired) in one period
    assert level1[names.index("B"), 0] > level1[names.index("I"), 0] + 0.01


BAD = [({"depth": 3}, "depth 3 is out of range 1-2"),
       ({"period": 0.0}, "period 0.0 s must be in (0, 5]"),
       ({"pose": (math.nan, 0.0, 0.0)}, "pose.x"),
       ({"fired": (("XX", 0.1),)}, "unknown limb 'XX'"),
       ({"fired": (("FL", -1.0),)}, "fired_ago of FL = -1.0 s"),
       ({"lead": -0.1}, "lead -0.1 s must be in [0, 5]"),
       ({"first": ("Z",)}, "first_primitives: unknown ['Z']")]


def test_bad_requests_are_refused_with_the_reason_and_the_node_keeps_serving(launch, probe):
    from soft_robot_interfaces.srv import Rollouts
    node = launch("rollout_node", params={"threads": 1})
    node.wait_for_log("ready in", timeout=240)
    client = probe.node.create_client(Rollouts, "/frog/rollouts")
    probe.wait_for_service(client, timeout=30)
    for change, message in BAD:
        res = probe.call(client, _request(**{"depth": 1, **change}), timeout=60)
        assert not res.success and message in res.message, (change, res.message)
        assert not res.transitions
    good = probe.call(client, _request(1), timeout=60)
    assert good.success and len(good.transitions) == 9 * 6
    node.wait_for_log("rollouts refused: depth 3", timeout=5)


def test_a_beam_after_a_lead_is_the_cores_coast_then_the_beams_pairs(launch, probe):
    """lead coasts the state (nothing fired) before the tree; first_primitives keeps only a beam."""
    from soft_robot_interfaces.srv import Rollouts

    from frog_planner.core.prediction import apply_transition
    from frog_sim.core.rollouts import Rollouts as CoreRollouts
    node = launch("rollout_node", params={"threads": 1})
    node.wait_for_log("ready in", timeout=240)
    client = probe.node.create_client(Rollouts, "/frog/rollouts")
    probe.wait_for_service(client, timeout=30)
    lead, beam = 0.4, ("B", "G")
    res = probe.call(client, _request(2, lead=lead, first=beam), timeout=120)
    assert res.success, res.message
    rows = np.asarray(res.transitions).reshape(-1, 6)
    names = list(res.primitive_names)
    inside = [names.index(b) for b in beam]
    finite1 = np.all(np.isfinite(rows[:9]), axis=1)
    finite2 = np.all(np.isfinite(rows[9:]).reshape(9, 9, 6), axis=(1, 2))
    assert sorted(np.flatnonzero(finite1)) == sorted(inside) == sorted(np.flatnonzero(finite2))
    with CoreRollouts(threads=1) as core:
        start = core.estimated_start(POSE, TWIST, {"FL": -0.3}, now=0.0)
        coasted = core.rollout_batch(start, [("I",)], period=lead).ends[("I",)]
        truth = core.rollout_batch(coasted, [(b, c) for b in beam for c in names], period=PERIOD)
    first_pose, _ = apply_transition(np.array(POSE), rows[inside])             # level 1 spans lead + T
    np.testing.assert_allclose(first_pose[:, :2], truth.pose[::9, 0, :2], atol=1e-7)
    level2 = np.concatenate([rows[9 + 9 * i:9 + 9 * (i + 1)] for i in inside])
    second_pose, _ = apply_transition(np.repeat(first_pose, 9, axis=0), level2)
    np.testing.assert_allclose(second_pose[:, :2], truth.pose[:, 1, :2], atol=1e-7)


def test_the_limbs_are_learned_from_consecutive_requests_and_forgotten_on_request(launch, probe):
    """A robot with a weak FR and a strong FL, simulated here (FrogSimulation, known limbs): each
    period's request carries its stamp, tracked pose, twist and firings, as planner_node sends
    them. The node's diagnostics then report the limbs near the truth, the rollouts use them (a
    C differs from the nominal robot's), ~/forget_limbs returns to nominal, and requests without
    a stamp teach nothing."""
    from diagnostic_msgs.msg import DiagnosticArray
    from soft_robot_interfaces.srv import Rollouts
    from std_srvs.srv import Trigger

    from frog_sim.core.simulation import FrogSimulation
    truth = {"FL": 1.2, "FR": 0.75, "BL": 1.1, "BR": 0.95}
    node = launch("rollout_node", params={"threads": 1})
    node.wait_for_log("ready in", timeout=240)
    client = probe.node.create_client(Rollouts, "/frog/rollouts")
    forget = probe.node.create_client(Trigger, "/rollout_node/forget_limbs")
    probe.wait_for_service(client, timeout=30)
    diag = {}

    def on_diag(msg):
        for st in msg.status:
            if "rollouts" in st.name:
                diag.update({kv.key: kv.value for kv in st.values})
    probe.node.create_subscription(DiagnosticArray, "/diagnostics", on_diag, 10)

    def request(sim, stamped=True):
        st = sim.rigid_body_state()
        fired = [(limb, sim.time - t) for limb, t in sim.last_firings().items() if sim.time - t < 10.0]
        req = _request(1, fired=fired, pose=(*st.com, st.heading), twist=(*st.body_velocity, st.yaw_rate),
                       period=1.43)
        if stamped:
            req.stamp.sec, req.stamp.nanosec = int(100 + sim.time), int(round((sim.time % 1) * 1e9)) % 10 ** 9
        return req

    sim = FrogSimulation()
    sim.set_limb_strength(truth)
    steps = int(round(1.43 / sim.time_step))
    for prim in "BCDBEFBGHBCDBEFBGHBB":
        res = probe.call(client, request(sim), timeout=60)
        assert res.success, res.message
        sim.execute_primitive(prim)
        sim.step(steps)
    probe.spin_until(lambda: float(diag.get("identification_updates", 0)) >= 19, 10, "19 updates in diagnostics")
    for limb, want in truth.items():
        assert float(diag[f"strength_{limb}"]) == pytest.approx(want, abs=0.06), diag
    # the tank torque is estimated alongside (default yaw_torque_sd); this tank is calm
    assert 0.0 < float(diag["yaw_torque_sd_Nm"]) < 9.2e-5 and abs(float(diag["yaw_torque_Nm"])) < 9.2e-5, diag
    learned = np.asarray(probe.call(client, _request(1), timeout=60).transitions).reshape(-1, 6)
    reply = probe.call(forget, Trigger.Request(), timeout=10)
    assert reply.success and "limbs back to nominal; were FL 1." in reply.message
    nominal = np.asarray(probe.call(client, _request(1), timeout=60).transitions).reshape(-1, 6)
    assert abs(learned[2, 2] - nominal[2, 2]) > 1e-3          # C turns otherwise with these limbs
    for _ in range(3):                                          # unstamped: nothing to chain
        assert probe.call(client, request(sim, stamped=False), timeout=60).success
        sim.execute_primitive("C")
        sim.step(steps)
    probe.spin_until(lambda: float(diag.get("identification_updates", -1)) == 0
                     and float(diag.get("strength_FL", 0)) == 1.0, 10, "nominal limbs, no update")
