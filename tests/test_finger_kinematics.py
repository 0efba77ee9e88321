"""kinematics_node as a real process: FK/IK services against the core, targets, the FollowCurve action.

One node (default finger, resolution 2, 5^3 configuration samples) serves the whole module;
the test process solves the same model with the core for independent truth.
"""

import math
import os
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from geometry_msgs.msg import Point, PointStamped
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from visualization_msgs.msg import Marker

sys.path.insert(0, str(Path(__file__).parent))
from ros_harness import GraphProbe, NodeProcess, acquire_domain  # noqa: E402

pytestmark = pytest.mark.system

QOS = QoSProfile(depth=200, reliability=ReliabilityPolicy.RELIABLE)
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
LAM = 0.2e-3


@pytest.fixture(scope="module")
def core():
    """The same finger solved in the test process (independent of the node)."""
    from softkin_fk.core.forward import ForwardSolver
    from softkin_fk.core.models import build_tendon_finger
    mesh = build_tendon_finger()
    return mesh, ForwardSolver(mesh)


@pytest.fixture(scope="module")
def finger(tmp_path_factory):
    """(node process, probe) on a module-wide exclusive domain."""
    mp = pytest.MonkeyPatch()
    domain = acquire_domain()
    for k in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_PYTHON_CHECK_FIELDS",
              "FASTDDS_BUILTIN_TRANSPORTS"):
        mp.setenv(k, domain.env[k])
    mp.delenv("ROS_LOCALHOST_ONLY", raising=False)
    log = tmp_path_factory.mktemp("finger") / "kinematics_node.log"
    proc = NodeProcess(["kinematics_node"], domain.env, log, "kinematics_node")
    probe = GraphProbe(domain)
    try:
        proc.wait_for_log(r"ready in", timeout=180)
        yield proc, probe
    finally:
        probe.close()
        code = proc.stop()
        print(f"\n----- kinematics_node log -----\n{proc.log_text()[-3000:]}")
        domain.release()
        mp.undo()
        assert code == 0 and proc.stopped_cleanly, f"kinematics_node did not stop cleanly (code {code})"


def _client(probe, srv_type, name):
    cli = probe.node.create_client(srv_type, name)
    probe.wait_for_service(cli, timeout=30)
    return cli


def _solver_stats(probe, timeout=30.0):
    """The values of kinematics_node's next diagnostics (1 Hz; published after this call began).

    Hearing it through a new subscription also means the node has matched the probe's earlier
    subscriptions, and that its executor has run past everything it had received before.
    """
    from diagnostic_msgs.msg import DiagnosticArray
    got = []
    sub = probe.node.create_subscription(
        DiagnosticArray, "/diagnostics", lambda m: got.extend(st for st in m.status if st.name.endswith(": solver")),
        10)
    try:
        probe.spin_until(lambda: got, timeout, "kinematics_node's diagnostics")
    finally:
        probe.node.destroy_subscription(sub)
    return {kv.key: kv.value for kv in got[0].values}


def _served(stats):
    """Streamed targets dealt with: solved (one command each) or superseded before they started."""
    return int(stats["solves"]) + int(stats["superseded_targets"])


def _fk(core, act):
    """Tip of an actuation, cold solve (the core's default active set)."""
    mesh, fs = core
    return fs.solve(np.asarray(act, float), tol=1e-9).marker(mesh, "tip")


def _fk_matches(core, act, point, tol=2e-6):
    """FK of ``act`` gives ``point``: a cable at rest (s = 1) admits a slack and a taut
    equilibrium, so both are solved from rest and the nearer one must match."""
    mesh, fs = core
    act = np.asarray(act, float)
    d = [np.linalg.norm(fs.solve(act, tol=1e-9, active0=a).marker(mesh, "tip") - point)
         for a in (None, np.ones(3, bool))]
    return min(d) < tol


def test_fk_service_matches_core(finger, core):
    from soft_robot_interfaces.srv import ForwardKinematics
    proc, probe = finger
    cli = _client(probe, ForwardKinematics, "/finger/forward_kinematics")
    for act in ([1.0, 1.0, 1.0], [0.95, 0.97, 0.98], [0.85, 1.0, 0.95]):
        res = probe.call(cli, ForwardKinematics.Request(actuation=act))
        assert res.success, res.message
        tip = np.array([res.tip.x, res.tip.y, res.tip.z])
        assert np.linalg.norm(tip - _fk(core, act)) < 1e-6
        assert len(res.marker_points) == 1 and "tip" in res.message
    # rest: the tip marker sits at the finger's top-right corner (120, 25, 12.5) mm
    res = probe.call(cli, ForwardKinematics.Request(actuation=[1.0, 1.0, 1.0]))
    assert [res.tip.x, res.tip.y, res.tip.z] == pytest.approx([0.12, 0.025, 0.0125], abs=1e-6)


def test_ik_service_reaches_fk_targets_and_reports_out_of_reach(finger, core):
    from soft_robot_interfaces.srv import SolveIk
    proc, probe = finger
    cli = _client(probe, SolveIk, "/finger/solve_ik")
    rng = np.random.default_rng(7)
    mesh = core[0]
    lo = np.array([a.bounds[0] for a in mesh.actuators])
    for _ in range(3):
        act = lo + (1.0 - lo) * rng.uniform(0.2, 0.8, 3)
        target = _fk(core, act)
        res = probe.call(cli, SolveIk.Request(target=Point(x=target[0], y=target[1], z=target[2])), timeout=60)
        reached = np.array([res.reached.x, res.reached.y, res.reached.z])
        assert res.success, res.message
        assert np.linalg.norm(reached - target) <= LAM
        assert res.residual_error == pytest.approx(np.linalg.norm(reached - target), abs=1e-9)
        # the returned actuation really produces the reported point (independent FK)
        assert _fk_matches(core, res.actuation, reached)
    # below the rest tip: the cables only pull the finger up, so this is out of reach
    far = np.array([0.118, 0.012, 0.0125])
    res = probe.call(cli, SolveIk.Request(target=Point(x=far[0], y=far[1], z=far[2])), timeout=60)
    reached = np.array([res.reached.x, res.reached.y, res.reached.z])
    assert not res.success and "out of reach" in res.message
    assert res.residual_error == pytest.approx(np.linalg.norm(reached - far), abs=1e-9)
    assert res.residual_error > 5e-3
    assert _fk_matches(core, res.actuation, reached)
    # no point of the sampled workspace is nearer than the one reported (within 0.3 mm)
    from softkin_fk.core.trajectory import sample_configuration_space
    cs = sample_configuration_space(core[1], 4)
    assert res.residual_error <= np.linalg.norm(cs.points - far, axis=1).min() + 3e-4


def test_bad_requests_are_refused_with_a_reason(finger):
    from soft_robot_interfaces.srv import ForwardKinematics, SolveIk
    proc, probe = finger
    ik = _client(probe, SolveIk, "/finger/solve_ik")
    fk = _client(probe, ForwardKinematics, "/finger/forward_kinematics")
    cases = [
        (ik, SolveIk.Request(target=Point(x=math.nan, y=0.05, z=0.0125)), "not finite"),
        (ik, SolveIk.Request(target=Point(x=100.0, y=54.0, z=12.5)), "max_target_distance"),
        (ik, SolveIk.Request(target=Point(x=0.1, y=0.05, z=0.0125), initial_guess=[1.0, 1.0]), "expected 3"),
        (fk, ForwardKinematics.Request(actuation=[1.0, 1.0]), "expected 3"),
        (fk, ForwardKinematics.Request(actuation=[0.5, 1.0, 1.0]), "outside its range"),
        (fk, ForwardKinematics.Request(actuation=[1.0, math.inf, 1.0]), "not finite"),
        # a non-finite or negative tolerance is refused before the solver
        (ik, SolveIk.Request(target=Point(x=0.1, y=0.05, z=0.0125), tolerance=math.nan), "tolerance nan"),
        (ik, SolveIk.Request(target=Point(x=0.1, y=0.05, z=0.0125), tolerance=math.inf), "tolerance inf"),
        (ik, SolveIk.Request(target=Point(x=0.1, y=0.05, z=0.0125), tolerance=-1.0), "tolerance -1.0"),
        (ik, SolveIk.Request(target=Point(x=0.1, y=0.05, z=0.0125), max_iterations=4_000_000_000),
         "max_iterations"),
    ]
    for cli, req, why in cases:
        res = probe.call(cli, req)
        assert not res.success and why in res.message, res.message
    assert proc.running()
    res = probe.call(fk, ForwardKinematics.Request(actuation=[1.0, 1.0, 1.0]))
    assert res.success


def test_targets_drive_setpoints_tip_and_shape(finger, core):
    proc, probe = finger
    mesh = core[0]
    setpoints, tips, shapes = [], [], []
    probe.node.create_subscription(JointState, "/finger/tendon_setpoints", setpoints.append, QOS)
    probe.node.create_subscription(PointStamped, "/finger/tip", tips.append, QOS)
    probe.node.create_subscription(Marker, "/finger/shape", shapes.append, LATCHED)
    pub = probe.node.create_publisher(PointStamped, "/finger/target", 10)
    probe.wait_matched(pub)
    probe.spin_until(lambda: shapes, 10, "latched shape")
    before = _solver_stats(probe)          # (and its setpoints and tips now reach the probe)

    def target(p, frame="finger_base"):
        m = PointStamped()
        m.header.frame_id = frame
        m.point = Point(x=float(p[0]), y=float(p[1]), z=float(p[2]))
        pub.publish(m)

    # refused: another frame, NaN, absurd; nothing is published for them
    target([0.1, 0.05, 0.0125], frame="world")
    target([math.nan, 0.05, 0.0125])
    target([5.0, 0.05, 0.0125])
    proc.wait_for_log(r"frame 'world' is not the base frame", timeout=10)
    proc.wait_for_log(r"target refused: .*not finite", timeout=10)
    proc.wait_for_log(r"target refused: .*max_target_distance", timeout=10)
    # refused on arrival: none reached the solver (its next diagnostics) and nothing was published
    assert _served(_solver_stats(probe)) == _served(before)
    assert setpoints == [] and tips == []

    act = np.array([0.93, 0.95, 0.97])
    goal = _fk(core, act)
    target(goal)
    probe.spin_until(lambda: setpoints and tips and len(shapes) >= 2, 30, "setpoints, tip and shape")
    # one solve for the one valid target: one command, nothing from the refused ones
    probe.spin_until(lambda: _served(_solver_stats(probe)) >= _served(before) + 1, 30, "the solve counted")
    assert len(setpoints) == 1 and len(tips) == 1
    sp, tip = setpoints[-1], tips[-1]
    assert sp.name == ["cable_0", "cable_1", "cable_2"]
    reached = np.array([tip.point.x, tip.point.y, tip.point.z])
    assert tip.header.frame_id == "finger_base" and np.linalg.norm(reached - goal) <= LAM
    # setpoints are cable pulls (1 - s) L whose FK is the published tip
    L = np.array([a.total_length for a in mesh.actuators])
    s = 1.0 - np.array(sp.position) / L
    assert _fk_matches(core, s, reached)
    assert np.all(np.array(sp.position) >= 0) and np.all(np.array(sp.position) <= 0.0086)
    m = shapes[-1]
    assert m.type == Marker.TRIANGLE_LIST and m.header.frame_id == "finger_base"
    assert len(m.points) == 3 * len(mesh.boundary_faces())
    assert max(p.y for p in m.points) > 0.03   # bent upwards: the rest finger is 25 mm tall

    # a burst of targets: older pending ones are superseded, the last one is served
    setpoints.clear()
    tips.clear()
    burst = [_fk(core, [0.93 - 0.004 * k, 0.95, 0.97]) for k in range(8)]
    start = _solver_stats(probe)
    for p in burst:
        target(p)
    probe.spin_until(lambda: tips and np.linalg.norm(
        np.array([tips[-1].point.x, tips[-1].point.y, tips[-1].point.z]) - burst[-1]) <= LAM, 30, "last target")
    # every target of the burst solved or superseded (the node's counts): no command is to come
    stats = {}

    def dealt_with():
        stats.update(_solver_stats(probe))
        return _served(stats) >= _served(start) + len(burst)
    probe.spin_until(dealt_with, 60, "the burst dealt with")
    solved = int(stats["solves"]) - int(start["solves"])
    probe.spin_until(lambda: len(setpoints) >= solved, 10, "a setpoint per solve")
    assert len(setpoints) == solved
    assert len(setpoints) < len(burst), "no target was superseded"
    assert np.linalg.norm(np.array([tips[-1].point.x, tips[-1].point.y, tips[-1].point.z]) - burst[-1]) <= LAM


def _send_goal(probe, goal, feedback, timeout=60.0):
    from rclpy.action import ActionClient
    from soft_robot_interfaces.action import FollowCurve
    client = ActionClient(probe.node, FollowCurve, "/finger/follow_curve")
    probe.spin_until(lambda: client.server_is_ready(), 30, "action server")
    fut = client.send_goal_async(goal, feedback_callback=lambda m: feedback.append(m.feedback))
    probe.spin_until(fut.done, timeout, "goal acceptance")
    return client, fut.result()


def test_follow_curve_L_feedback_per_waypoint_and_services_stay_responsive(finger, core):
    from soft_robot_interfaces.action import FollowCurve
    from soft_robot_interfaces.srv import SolveIk
    from softkin_fk.core.curves import curve_L
    proc, probe = finger
    setpoints, feedback = [], []
    probe.node.create_subscription(JointState, "/finger/tendon_setpoints", setpoints.append, QOS)
    # the feedback topic itself: rclpy's ActionClient drops the feedback that arrives after the
    # result (a service reply, which overtook the last 3 of 55 feedbacks on a loaded machine)
    probe.node.create_subscription(FollowCurve.Impl.FeedbackMessage, "/finger/follow_curve/_action/feedback",
                                   feedback.append, QOS)
    _solver_stats(probe)            # the node's setpoints and feedback now reach the probe
    ik = _client(probe, SolveIk, "/finger/solve_ik")
    fb = []
    t0 = time.monotonic()
    client, handle = _send_goal(probe, FollowCurve.Goal(curve="L"), fb)
    assert handle.accepted
    res_fut = handle.get_result_async()
    # a service call while the trajectory runs is answered between waypoints
    probe.spin_until(lambda: len(fb) >= 3, 30, "first feedback")
    t_call = time.monotonic()
    q = probe.call(ik, SolveIk.Request(target=Point(x=0.1, y=0.055, z=0.0125)), timeout=30)
    call_latency = time.monotonic() - t_call
    probe.spin_until(res_fut.done, 60, "result")
    wall = time.monotonic() - t0

    def ours():
        return [m.feedback for m in feedback if bytes(m.goal_id.uuid) == bytes(handle.goal_id.uuid)]
    probe.spin_until(lambda: len(ours()) >= 55, 10, "the feedback of every waypoint")
    fb = ours()
    res = res_fut.result().result
    P = curve_L()
    assert q.success and call_latency < 3.0
    assert not res_fut.done() or len(fb) < 55 or fb[-1].index == 54
    assert [f.index for f in fb] == list(range(55)) and all(f.total == 55 for f in fb)
    assert res.success and res.waypoints_reached == 55, res.message
    assert len(res.errors) == 55 and max(res.errors) <= LAM
    tg = np.array([[p.x, p.y, p.z] for p in res.targets])
    rc = np.array([[p.x, p.y, p.z] for p in res.reached])
    assert np.allclose(tg, P, atol=1e-12)
    assert np.allclose(np.linalg.norm(rc - tg, axis=1), res.errors, atol=1e-12)
    acts = np.array(res.actuations).reshape(55, 3)
    for k in (0, 27, 54):   # independent FK of reported actuations
        assert _fk_matches(core, acts[k], rc[k])
    probe.spin_until(lambda: len(setpoints) >= 55, 10, "55 setpoints")
    _solver_stats(probe)        # the node's next diagnostics: any further setpoint would be here
    assert len(setpoints) == 55
    print(f"'L' through the action: {wall:.2f} s wall ({res.solve_seconds:.2f} s solving); "
          f"SolveIk during it answered in {call_latency * 1e3:.0f} ms")


def test_follow_curve_cancel_and_bad_goals(finger):
    from action_msgs.msg import GoalStatus
    from soft_robot_interfaces.action import FollowCurve
    proc, probe = finger
    fb = []
    client, handle = _send_goal(probe, FollowCurve.Goal(curve="flame", dry_run=True), fb)
    assert handle.accepted
    probe.spin_until(lambda: len(fb) >= 2, 30, "feedback")
    # a streamed target while a trajectory runs is refused (it would fight the trajectory)
    pub = probe.node.create_publisher(PointStamped, "/finger/target", 10)
    probe.wait_matched(pub)
    m = PointStamped()
    m.header.frame_id = "finger_base"
    m.point = Point(x=0.1, y=0.055, z=0.0125)
    pub.publish(m)
    proc.wait_for_log("target refused: a follow_curve goal is running", timeout=10)
    probe.spin_until(lambda: len(fb) >= 5, 30, "5 feedbacks")
    cancel = handle.cancel_goal_async()
    res_fut = handle.get_result_async()
    probe.spin_until(res_fut.done, 30, "canceled result")
    out = res_fut.result()
    assert out.status == GoalStatus.STATUS_CANCELED
    n = len(out.result.errors)
    assert 5 <= n < 85 and "canceled" in out.result.message
    assert cancel.done()
    # bad goals: unknown curve, NaN waypoint, wrong frame -> aborted with the reason
    for goal, why in ((FollowCurve.Goal(curve="spiral"), "unknown curve"),
                      (FollowCurve.Goal(waypoints=[Point(x=math.nan)]), "not finite"),
                      (FollowCurve.Goal(curve="L", frame_id="world"), "base frame"),
                      (FollowCurve.Goal(), "no curve name")):
        client, handle = _send_goal(probe, goal, [])
        res_fut = handle.get_result_async()
        probe.spin_until(res_fut.done, 30, "aborted result")
        assert res_fut.result().status == GoalStatus.STATUS_ABORTED
        assert why in res_fut.result().result.message, res_fut.result().result.message
    assert proc.running()
    assert os.environ["ROS_PYTHON_CHECK_FIELDS"] == "1"


def test_non_finite_tolerance_and_huge_counts_move_nothing(finger):
    """A goal with ``tolerance: .nan`` or a huge ``n_waypoints`` is aborted with the field named,
    and no setpoint is sent."""
    from action_msgs.msg import GoalStatus
    from soft_robot_interfaces.action import FollowCurve
    proc, probe = finger
    setpoints = []
    probe.node.create_subscription(JointState, "/finger/tendon_setpoints", setpoints.append, QOS)
    _solver_stats(probe)            # the node's setpoints now reach the probe
    for goal, why in ((FollowCurve.Goal(curve="L", n_waypoints=3, tolerance=math.nan), "tolerance nan"),
                      (FollowCurve.Goal(curve="L", n_waypoints=3, tolerance=-1.0), "tolerance -1.0"),
                      (FollowCurve.Goal(curve="L", n_waypoints=3, tolerance=math.inf), "tolerance inf"),
                      (FollowCurve.Goal(curve="L", n_waypoints=4_000_000_000), "n_waypoints 4000000000")):
        client, handle = _send_goal(probe, goal, [])
        res_fut = handle.get_result_async()
        probe.spin_until(res_fut.done, 30, "aborted result")
        out = res_fut.result()
        assert out.status == GoalStatus.STATUS_ABORTED and why in out.result.message, out.result.message
    # a valid target afterwards is the only command that reaches the setpoints
    pub = probe.node.create_publisher(PointStamped, "/finger/target", 10)
    probe.wait_matched(pub)
    m = PointStamped()
    m.header.frame_id = "finger_base"
    m.point = Point(x=0.1, y=0.055, z=0.0125)
    pub.publish(m)
    probe.spin_until(lambda: setpoints, 30, "the valid target's setpoints")
    _solver_stats(probe)            # the node's next diagnostics: a further setpoint would be here
    assert len(setpoints) == 1 and proc.running()


EXAMPLES = Path(__file__).resolve().parents[1] / "ros_ws" / "src" / "softkin_fk" / "examples"


def test_user_mesh_and_spec(launch, probe):
    """The node on a user's gmsh model + JSON spec, against the core loading the same files."""
    from soft_robot_interfaces.action import FollowCurve
    from soft_robot_interfaces.srv import ForwardKinematics, SolveIk
    from softkin_fk.core.forward import ForwardSolver
    from softkin_fk.core.mesh_spec import load_mesh_with_spec
    msh, spec = EXAMPLES / "finger_mm.msh", EXAMPLES / "finger_mm.json"
    node = launch("kinematics_node", params=dict(mesh_file=str(msh), spec_file=str(spec), config_samples=0,
                                                 frame_id="part"))
    node.wait_for_log("ready in", timeout=120)
    mesh = load_mesh_with_spec(str(msh), str(spec))
    act = [0.98, 0.99, 0.98]
    truth = ForwardSolver(mesh).solve(act, tol=1e-9).marker(mesh, "tip")
    fk = _client(probe, ForwardKinematics, "/finger/forward_kinematics")
    res = probe.call(fk, ForwardKinematics.Request(actuation=act), timeout=60)
    assert res.success and np.linalg.norm(np.array([res.tip.x, res.tip.y, res.tip.z]) - truth) < 1e-6
    ik = _client(probe, SolveIk, "/finger/solve_ik")
    r = probe.call(ik, SolveIk.Request(target=Point(x=truth[0], y=truth[1], z=truth[2])), timeout=120)
    assert r.success and r.residual_error <= LAM, r.message
    fb = []
    client, handle = _send_goal(probe, FollowCurve.Goal(curve="L"), fb)
    res_fut = handle.get_result_async()
    probe.spin_until(res_fut.done, 30, "aborted result")
    assert "finger's workspace" in res_fut.result().result.message
