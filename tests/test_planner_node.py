"""planner_node as a real process: decisions, latched path, idle reasons, bad input."""

import math
import re
import time

import pytest
from nav_msgs.msg import Odometry
from nav_msgs.msg import Path as PathMsg
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_srvs.srv import Trigger

pytestmark = pytest.mark.system

QOS = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)




def _stamp(m):
    return m.header.stamp.sec + m.header.stamp.nanosec * 1e-9


def _feed_until(probe, pub, predicate, timeout, what):
    """Publish odometry 3 cm left of the line (heading along it) every 50 ms until ``predicate()``."""
    def fed():
        pub.publish(_odom(0.05, 0.03, 0.0))
        return predicate()
    return probe.spin_until(fed, timeout, what)


def _same_tick(probe, prims, status_msg, timeout=10.0):
    """The primitive published with ``status_msg`` (the planner stamps both of a decision alike)."""
    probe.spin_until(lambda: any(_stamp(p) == _stamp(status_msg) for p in prims), timeout,
                     "the primitive of the status' decision")
    return next(p for p in prims if _stamp(p) == _stamp(status_msg))


def _odom(x, y, yaw, v=0.01):
    m = Odometry()
    m.header.frame_id, m.child_frame_id = "tank", "frog"
    m.pose.pose.position.x, m.pose.pose.position.y = x, y
    m.pose.pose.orientation.z, m.pose.pose.orientation.w = math.sin(yaw / 2), math.cos(yaw / 2)
    m.twist.twist.linear.x = v
    now = time.time()              # odometry is stamped (an unstamped one is refused, issue 23.9)
    m.header.stamp.sec, m.header.stamp.nanosec = int(now), int((now % 1) * 1e9)
    return m


def test_decides_every_period_and_reports_idle_reasons(launch, probe, library):
    from soft_robot_interfaces.msg import PlannerStatus, Primitive
    node = launch("planner_node", params={"library_file": str(library), "period": 0.5,
                                          "path_type": "line", "odom_topic": "/test/odom",
                                          "state_topic": ""})
    prims, status, paths = [], [], []
    probe.node.create_subscription(Primitive, "/frog/primitive", prims.append, QOS)
    probe.node.create_subscription(PlannerStatus, "/frog/planner/status", status.append, QOS)
    odom_pub = probe.node.create_publisher(Odometry, "/test/odom", QOS)
    node.wait_for_log("following a line path", timeout=60)
    probe.wait_matched(odom_pub)

    # no odometry yet: primitive I, the state and reason in the status (no fake costs), logged once
    probe.spin_until(lambda: len(prims) >= 2 and len(status) >= 2, 10, "idle primitives")
    assert all(p.id == Primitive.ID_I and p.name == "I" for p in prims)
    s = status[-1]
    assert s.state == PlannerStatus.STATE_WAITING and "no odometry on /test/odom" in s.message
    assert math.isnan(s.total_cost) and math.isnan(s.cost_distance) and math.isnan(s.distance_to_path)
    node.wait_for_log(r"no odometry on /test/odom yet; publishing primitive I", timeout=5)
    assert len(node.log_text().split("no odometry on /test/odom")) == 2, "the reason is logged once"

    # the latched path reaches a late subscriber
    probe.node.create_subscription(PathMsg, "/frog/path", paths.append, LATCHED)
    probe.spin_until(lambda: paths, 10, "latched /frog/path")
    assert len(paths[0].poses) == 100 and paths[0].header.frame_id == "tank"

    # odometry 3 cm left of the line, heading along it: a real decision with status
    prims.clear()
    status.clear()

    def decided():
        return [s for s in status if s.state == PlannerStatus.STATE_FOLLOWING]
    _feed_until(probe, odom_pub, decided, 30, "a decision with a cost")
    s = decided()[-1]
    assert s.distance_to_path == pytest.approx(0.03, abs=1e-3)
    assert 0.0 < s.path_progress < 0.3
    assert s.primitive_name == "ABCDEFGHI"[s.primitive_id] and s.total_cost > 0
    assert _same_tick(probe, prims, s).id == s.primitive_id

    # the decision carries the stamp of the state it was decided on: the odometry's (no tracker state)
    p = _same_tick(probe, prims, s)
    assert p.state_stamp.sec > 0 and 0.0 <= _stamp(p) - (p.state_stamp.sec + p.state_stamp.nanosec * 1e-9) <= 0.5

    # non-finite odometry is rejected, the node keeps running
    odom_pub.publish(_odom(float("nan"), 0.0, 0.0))
    node.wait_for_log("ignored odometry: .*not finite", timeout=5)
    assert node.running()

    # no odometry for longer than max_state_age_s (0.5 s): back to I with the reason
    node.wait_for_log(r"the state is .* s old \(max_state_age_s 0.5 s\); publishing primitive I", timeout=30)
    probe.spin_until(lambda: any("s old" in s.message for s in status), 10, "a status saying the state is old")
    s = next(s for s in status if "s old" in s.message)
    assert s.state == PlannerStatus.STATE_WAITING
    assert _same_tick(probe, prims, s).id == Primitive.ID_I

    # ~/stop and ~/start
    stop = probe.node.create_client(Trigger, "/planner_node/stop")
    start = probe.node.create_client(Trigger, "/planner_node/start")
    probe.wait_for_service(stop)
    assert probe.call(stop, Trigger.Request()).success
    node.wait_for_log(r"stopped \(call ~/start\)", timeout=5)
    status.clear()
    probe.spin_until(lambda: status, 5, "status while stopped")
    assert status[-1].state == PlannerStatus.STATE_IDLE
    reply = probe.call(start, Trigger.Request())
    assert reply.success and "following the line path" in reply.message
    assert node.stop() == 0 and node.stopped_cleanly


def test_missing_or_corrupt_library_keeps_node_up_publishing_I(launch, probe, tmp_path):
    from soft_robot_interfaces.msg import Primitive
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"this is not a library")
    node = launch("planner_node", params={"library_file": str(bad), "period": 0.3})
    prims = []
    probe.node.create_subscription(Primitive, "/frog/primitive", prims.append, QOS)
    node.wait_for_log(r"cannot use library .*bad\.npz", timeout=60)
    probe.spin_until(lambda: len(prims) >= 2, 10, "primitives")
    assert {p.id for p in prims} == {Primitive.ID_I}
    # ~/start says why it cannot follow instead of pretending to
    start = probe.node.create_client(Trigger, "/planner_node/start")
    probe.wait_for_service(start)
    reply = probe.call(start, Trigger.Request())
    assert not reply.success and "bad.npz" in reply.message
    assert node.running()
    assert node.stop() == 0


@pytest.mark.parametrize("params,message", [
    ({"depth": 9}, "depth"), ({"path_type": "spiral"}, "path_type"),
    ({"period": -1.0}, "period"), ({"path_type": "waypoints"}, "waypoint_file"),
    ({"velocity_lookahead": -1.0}, "velocity_lookahead"),
    ({"goal_lateral_tolerance": -0.01}, "goal_lateral_tolerance"), ({"stall_speed": -0.1}, "stall_speed"),
    ({"replan_interval": 0.5, "transitions": "simulator"}, "replan_interval"),
    ({"replan_interval": 0.6}, "not below max_state_age_s"),
    ({"transitions": "simulator", "reanchor": False}, "reanchor false"), ({"max_state_age_s": 0.0}, "max_state_age_s")])
def test_bad_parameters_exit_with_a_message(launch, params, message):
    node = launch("planner_node", params=params)
    assert node.wait(60) == 2
    assert "fatal configuration error" in node.log_text() and message in node.log_text()


def test_frog_stop_stops_deciding_at_once(launch, probe, library):
    """/frog/stop (std_msgs/Empty), the run's one stop: the planner goes idle and publishes I until ~/start."""
    from soft_robot_interfaces.msg import PlannerStatus, Primitive
    from std_msgs.msg import Empty
    node = launch("planner_node", params={"library_file": str(library), "period": 0.5,
                                          "path_type": "line", "odom_topic": "/test/odom",
                                          "state_topic": ""})
    prims, status = [], []
    probe.node.create_subscription(Primitive, "/frog/primitive", prims.append, QOS)
    probe.node.create_subscription(PlannerStatus, "/frog/planner/status", status.append, QOS)
    odom_pub = probe.node.create_publisher(Odometry, "/test/odom", QOS)
    stop = probe.node.create_publisher(Empty, "/frog/stop", QOS)
    node.wait_for_log("following a line path", timeout=60)
    probe.wait_matched(stop)
    probe.wait_matched(odom_pub)
    _feed_until(probe, odom_pub, lambda: any(s.state == PlannerStatus.STATE_FOLLOWING for s in status), 30,
                "a decision")
    stop.publish(Empty())
    node.wait_for_log("stop received on /frog/stop", timeout=5)
    # from the first idle status on (decisions already sent may still arrive before it), with
    # odometry still coming: three more periods, only I (its primitives carry the status' stamps)
    _feed_until(probe, odom_pub, lambda: any(s.state == PlannerStatus.STATE_IDLE for s in status), 10,
                "the idle status after the stop")
    t_idle = _stamp(next(s for s in status if s.state == PlannerStatus.STATE_IDLE))
    after = [status, prims]

    def since_idle():
        after[:] = [[s for s in status if _stamp(s) >= t_idle], [p for p in prims if _stamp(p) >= t_idle]]
        return len(after[0]) >= 4 and len(after[1]) >= 4
    _feed_until(probe, odom_pub, since_idle, 30, "four periods after the stop")
    assert all(p.name == "I" for p in after[1]), [p.name for p in after[1]]
    assert all(s.state == PlannerStatus.STATE_IDLE for s in after[0]), [s.message for s in after[0]]
    assert node.stop() == 0


def _stamped_odom(x, y, yaw, age_s):
    m = _odom(x, y, yaw)
    t = time.time() - age_s
    m.header.stamp.sec, m.header.stamp.nanosec = int(t), int((t % 1) * 1e9)
    return m


def test_odometry_with_an_old_stamp_blocks_decisions_and_is_counted(launch, probe, library):
    """A tracker republishing old poses (fresh arrivals, old stamps): primitive I with the stamp's age in
    the status and a count in the diagnostics; fresh stamps decide again, with the pose's age in the status."""
    from diagnostic_msgs.msg import DiagnosticArray
    from soft_robot_interfaces.msg import PlannerStatus, Primitive
    node = launch("planner_node", params={"library_file": str(library), "period": 0.5, "max_state_age_s": 1.0,
                                          "path_type": "line", "odom_topic": "/test/odom",
                                          "state_topic": ""})
    prims, status, diags = [], [], []
    probe.node.create_subscription(Primitive, "/frog/primitive", prims.append, QOS)
    probe.node.create_subscription(PlannerStatus, "/frog/planner/status", status.append, QOS)
    probe.node.create_subscription(DiagnosticArray, "/diagnostics", diags.append, QOS)
    odom_pub = probe.node.create_publisher(Odometry, "/test/odom", QOS)
    node.wait_for_log("following a line path", timeout=60)
    probe.wait_matched(odom_pub)

    def feed_until(make, predicate, timeout, what):
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            odom_pub.publish(make())
            probe.spin_for(0.05)
            if predicate():
                return
        raise TimeoutError(f"{what} not reached within {timeout} s")

    def stale_values():
        return [int(kv.value) for d in diags for s in d.status if s.name == "planner_node: planner"
                for kv in s.values if kv.key == "waited_decisions"]

    # before any odometry: waiting, state_age NaN, and the refusals are counted already
    probe.spin_until(lambda: status and stale_values() and stale_values()[-1] >= 1, 10, "a counted refusal")
    assert status[-1].state == PlannerStatus.STATE_WAITING and math.isnan(status[-1].state_age)

    # stamped 3 s ago (bound 1 s), delivered now: refused, the age in the message and field
    feed_until(lambda: _stamped_odom(0.05, 0.03, 0.0, 3.0),
               lambda: any("the state is" in s.message for s in status), 10, "an old-state status")
    prims.clear()
    status.clear()
    n_before = stale_values()[-1]
    feed_until(lambda: _stamped_odom(0.05, 0.03, 0.0, 3.0), lambda: len(status) >= 3, 10, "3 statuses")
    assert all(s.state == PlannerStatus.STATE_WAITING and "the state is" in s.message for s in status), \
        [s.message for s in status]
    assert all(2.9 < s.state_age < 4.0 for s in status), [s.state_age for s in status]
    assert prims and all(p.id == Primitive.ID_I for p in prims)
    node.wait_for_log(r"the state is 3\.\d+ s old \(max_state_age_s 1 s\); publishing primitive I", timeout=5)
    assert node.log_text().count("the state is 3.") == 1, "the reason is logged once, not every period"
    probe.spin_until(lambda: stale_values()[-1] >= n_before + 3, 10, "the diagnostics' count to grow")

    # a stamp far in the future (another clock): refused too
    feed_until(lambda: _stamped_odom(0.05, 0.03, 0.0, -100.0),
               lambda: any("in the future" in s.message for s in status), 10, "a future-stamp status")

    # fresh stamps: decisions again, each with the age of its pose (small, non-negative)
    feed_until(lambda: _stamped_odom(0.05, 0.03, 0.0, 0.0),
               lambda: any(s.state == PlannerStatus.STATE_FOLLOWING for s in status), 10, "a decision")
    decided = [s for s in status if s.state == PlannerStatus.STATE_FOLLOWING]
    assert all(0.0 <= s.state_age < 1.0 for s in decided), [s.state_age for s in decided]
    assert node.stop() == 0


def test_status_says_where_the_path_is_tighter_than_the_frog_can_turn(launch, probe, library):
    """The synthetic kinematics' tightest steady circle is u / w = 5 mm/s / 0.5 rad/s = 1 cm (G, H);
    a paper sine scaled to 7 cm has a smallest radius l A / f^2 = 5.95 mm: the status says so and
    the node warns once; switched live to a line, nothing is too tight."""
    from rcl_interfaces.msg import Parameter as ParameterMsg
    from rcl_interfaces.msg import ParameterType, ParameterValue
    from rcl_interfaces.srv import SetParameters
    from soft_robot_interfaces.msg import PlannerStatus
    length = 0.07
    node = launch("planner_node", params={"library_file": str(library), "period": 0.5, "path_type": "sine",
                                          "path_length": length, "feasibility_lookahead": 0.1,
                                          "odom_topic": "/test/odom", "state_topic": ""})
    status = []
    probe.node.create_subscription(PlannerStatus, "/frog/planner/status", status.append, QOS)
    odom_pub = probe.node.create_publisher(Odometry, "/test/odom", QOS)
    node.wait_for_log("following a sinusoid path", timeout=60)
    assert "tightest steady turn: left 1.0 cm (H), right 1.0 cm (G)" in node.log_text() or \
        "tightest steady turn: left 1.0 cm (G), right 1.0 cm (H)" in node.log_text(), node.log_text()
    node.wait_for_log(r"the sinusoid path bends tighter than the frog can turn over \d+ % of its length", timeout=5)
    probe.wait_matched(odom_pub)

    def following():
        odom_pub.publish(_odom(0.0, 0.0, 0.0))
        return any(s.state == PlannerStatus.STATE_FOLLOWING for s in status)
    probe.spin_until(following, 20, "a decision on the sine")
    s = [s for s in status if s.state == PlannerStatus.STATE_FOLLOWING][-1]
    assert s.path_too_tight
    assert s.turn_radius_limit == pytest.approx(0.01, rel=0.05)
    assert s.path_radius_ahead == pytest.approx(length * 8.5 / 10.0 ** 2, rel=0.05)
    assert "tighter than the frog's 1.0 cm turn: cutting" in s.message, s.message

    setter = probe.node.create_client(SetParameters, "/planner_node/set_parameters")
    probe.wait_for_service(setter)
    p = ParameterMsg(name="path_type", value=ParameterValue(type=ParameterType.PARAMETER_STRING, string_value="line"))
    assert probe.call(setter, SetParameters.Request(parameters=[p])).results[0].successful
    node.wait_for_log("the line path is within the frog's turning circle everywhere", timeout=10)
    status.clear()

    def straight():
        odom_pub.publish(_odom(0.0, 0.0, 0.0))
        return any(s.state == PlannerStatus.STATE_FOLLOWING for s in status)
    probe.spin_until(straight, 20, "a decision on the line")
    s = [s for s in status if s.state == PlannerStatus.STATE_FOLLOWING][-1]
    assert not s.path_too_tight and s.path_radius_ahead == math.inf and "cutting" not in s.message


def test_replan_interval_decides_on_the_mean_pose_and_publishes_the_newest_at_the_tick(launch, probe, library):
    """The paper's asynchronous loop: odometry alternating 2 and 4 cm left of the line gives
    decisions made on its mean (3 cm), published at the period ticks."""
    from soft_robot_interfaces.msg import PlannerStatus, Primitive
    node = launch("planner_node", params={"library_file": str(library), "period": 0.6, "replan_interval": 0.2,
                                          "path_type": "line", "odom_topic": "/test/odom",
                                          "state_topic": ""})
    prims, status = [], []
    probe.node.create_subscription(Primitive, "/frog/primitive", prims.append, QOS)
    probe.node.create_subscription(PlannerStatus, "/frog/planner/status", status.append, QOS)
    odom_pub = probe.node.create_publisher(Odometry, "/test/odom", QOS)
    node.wait_for_log("following a line path", timeout=60)
    probe.wait_matched(odom_pub)
    k = [0]

    def queued():
        k[0] += 1
        odom_pub.publish(_odom(0.05, 0.02 if k[0] % 2 else 0.04, 0.0))
        return [s for s in status if s.state == PlannerStatus.STATE_FOLLOWING]
    probe.spin_until(lambda: len(queued()) >= 3, 30, "three queued decisions published")
    decided = queued()
    averaged = 0
    for s in decided:
        n = int(re.search(r"queued decision on the mean of (\d+) states", s.message).group(1))
        # the mean of n alternating poses: 3 cm, or 3 -+ 1/n cm for odd n; the newest is 2 or 4 cm
        assert s.distance_to_path == pytest.approx(0.03, abs=0.01 / n + 2e-4), (n, s.distance_to_path)
        averaged += n >= 2
        assert _same_tick(probe, prims, s).id == s.primitive_id
    assert averaged >= 2, [s.message for s in decided]
    ticks = sorted({_stamp(s) for s in status})
    assert min(b - a for a, b in zip(ticks, ticks[1:])) > 0.45            # one decision per 0.6 s period
    assert node.stop() == 0 and node.stopped_cleanly


def test_replan_slower_than_the_period_sends_each_decision_once(launch, probe, library):
    """A queued decision is executed at one tick only: a tick with no new one publishes I."""
    from soft_robot_interfaces.msg import PlannerStatus
    node = launch("planner_node", params={"library_file": str(library), "period": 0.3, "replan_interval": 0.9,
                                          "max_state_age_s": 1.5,
                                          "path_type": "line", "odom_topic": "/test/odom",
                                          "state_topic": ""})
    status = []
    probe.node.create_subscription(PlannerStatus, "/frog/planner/status", status.append, QOS)
    odom_pub = probe.node.create_publisher(Odometry, "/test/odom", QOS)
    node.wait_for_log("following a line path", timeout=60)
    probe.wait_matched(odom_pub)

    def states():
        return [s.state for s in status]
    following = PlannerStatus.STATE_FOLLOWING
    _feed_until(probe, odom_pub, lambda: states().count(following) >= 3, 30, "three decisions")
    first = states().index(following)
    seq = status[first:]
    assert states().count(following) < 0.6 * len(seq), states()      # about one tick in three
    for a, b in zip(seq, seq[1:]):
        if a.state == following:                       # the tick after a decision has nothing new
            assert b.state == PlannerStatus.STATE_WAITING and "no new decision" in b.message, b.message
            break
    assert node.stop() == 0 and node.stopped_cleanly


def test_a_predicted_pose_is_decided_on_by_the_age_of_its_measurement(launch, probe, library):
    """With the tracker's state (frog/tracker/state, the default), odometry stamped now whose
    measurement is 0.8 s old (a pose the tracker predicted) blocks decisions; a measured pose is
    decided on, and the primitive carries its measurement's stamp."""
    from soft_robot_interfaces.msg import PlannerStatus, Primitive, TrackerState
    node = launch("planner_node", params={"library_file": str(library), "period": 0.3, "path_type": "line",
                                          "odom_topic": "/test/odom"})
    prims, status = [], []
    probe.node.create_subscription(Primitive, "/frog/primitive", prims.append, QOS)
    probe.node.create_subscription(PlannerStatus, "/frog/planner/status", status.append, QOS)
    odom_pub = probe.node.create_publisher(Odometry, "/test/odom", QOS)
    state_pub = probe.node.create_publisher(TrackerState, "/frog/tracker/state", QOS)
    node.wait_for_log("following a line path", timeout=60)
    probe.wait_matched(odom_pub)
    probe.wait_matched(state_pub)

    def feed(measured_age):
        def fed():
            odom = _odom(0.05, 0.03, 0.0)
            st = TrackerState(state=TrackerState.STATE_COASTING if measured_age else TrackerState.STATE_TRACKING)
            st.header.stamp = odom.header.stamp
            t = _stamp(odom) - measured_age
            st.state_stamp.sec, st.state_stamp.nanosec = int(t), int(round((t % 1) * 1e9)) % 1_000_000_000
            state_pub.publish(st)
            odom_pub.publish(odom)
            return fed.result()
        return fed

    feed.__defaults__ = None
    coasting = feed(0.8)
    coasting.result = lambda: len([s for s in status if "the state is 0.8" in s.message]) >= 3
    probe.spin_until(coasting, 20, "three statuses refusing a predicted pose")
    assert not [s for s in status if s.state == PlannerStatus.STATE_FOLLOWING]
    assert all(p.id == Primitive.ID_I for p in prims)
    measured = feed(0.0)
    measured.result = lambda: any(s.state == PlannerStatus.STATE_FOLLOWING for s in status)
    probe.spin_until(measured, 20, "a decision on a measured pose")
    s = next(s for s in status if s.state == PlannerStatus.STATE_FOLLOWING)
    p = _same_tick(probe, prims, s)
    assert p.id != Primitive.ID_I and 0.0 <= s.state_age < 0.5
    assert node.stop() == 0 and node.stopped_cleanly
