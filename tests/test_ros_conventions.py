"""The graph as a ROS 2 user meets it: namespaces, clocks, live parameters, start-up warnings.

Real node processes on an isolated domain; parameters are described and set through the
parameter services that ``ros2 param describe/set`` use.
"""

import math

import pytest
from diagnostic_msgs.msg import DiagnosticArray
from nav_msgs.msg import Odometry
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterType, ParameterValue
from rcl_interfaces.srv import DescribeParameters, GetParameters, SetParameters
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from std_srvs.srv import Trigger

pytestmark = pytest.mark.system

QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)




def _stamp(msg) -> float:
    return msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9


def _double(name, value):
    return ParameterMsg(name=name, value=ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=value))


def _integer(name, value):
    return ParameterMsg(name=name, value=ParameterValue(type=ParameterType.PARAMETER_INTEGER, integer_value=value))


def test_two_frogs_in_two_namespaces_do_not_cross_talk(launch, probe, library):
    """Each namespace has its own simulator and planner; status distances are each frog's own."""
    offsets = {"/frog1": 0.0, "/frog2": 0.2}
    nodes = []
    for ns, y in offsets.items():
        nodes.append(launch("sim_node", params={"initial_y": y, "odom_alias_topic": "frog/odom"},
                            remap={"__ns": ns}, name=f"sim{ns[-1]}"))
        nodes.append(launch("planner_node", params={"library_file": str(library), "period": 0.5,
                                                    "path_type": "line", "state_topic": ""},
                            remap={"__ns": ns}, name=f"planner{ns[-1]}"))
    from soft_robot_interfaces.msg import PlannerStatus
    status = {ns: [] for ns in offsets}
    odom = {ns: [] for ns in offsets}
    for ns in offsets:
        probe.node.create_subscription(PlannerStatus, f"{ns}/frog/planner/status", status[ns].append, QOS)
        probe.node.create_subscription(Odometry, f"{ns}/frog/sim/odom", odom[ns].append, QOS)
    for ns in offsets:
        probe.wait_for_node(f"{ns}/sim_node", timeout=120)
        probe.wait_for_node(f"{ns}/planner_node", timeout=120)

    def following():
        # and the probe has heard each simulator: its subscriptions may match after the planners' did
        return all(odom[ns] and any(s.state == PlannerStatus.STATE_FOLLOWING for s in status[ns]) for ns in offsets)
    probe.spin_until(following, 60, "both planners following and both simulators heard")
    for ns, y in offsets.items():
        # one simulator and one planner behind each namespaced topic, nothing in the root namespace
        assert probe.node.count_publishers(f"{ns}/frog/sim/odom") == 1
        assert probe.node.count_publishers(f"{ns}/frog/primitive") == 1
        assert probe.node.count_subscribers(f"{ns}/frog/primitive") == 1
        assert probe.node.count_subscribers(f"{ns}/frog/odom") == 1
        first = next(s for s in status[ns] if s.state == PlannerStatus.STATE_FOLLOWING)
        # its own frog's offset (cross-talk would give the other's: 0.2 m apart); a few cm of
        # margin, since the first status received may come after a kick or two
        assert first.distance_to_path == pytest.approx(y, abs=0.05), (ns, first.distance_to_path)
        # half the frogs' separation: the frog swims a few cm toward its path meanwhile
        assert abs(odom[ns][-1].pose.pose.position.y - y) < 0.1
    assert probe.node.count_publishers("/frog/sim/odom") == 0
    assert probe.node.count_publishers("/frog/primitive") == 0
    for n in nodes:
        assert n.stop() == 0 and n.stopped_cleanly


def test_planner_parameters_describe_ranges_and_live_sets_are_validated(launch, probe, library):
    node = launch("planner_node", params={"library_file": str(library), "period": 0.5,
                                          "yaw_rate_weigth": 2.0})   # misspelt on purpose
    node.wait_for_log("following a line path", timeout=60)
    # the misspelt override is reported with the closest declared name
    node.wait_for_log(r"'yaw_rate_weigth' is not a parameter of this node .*did you mean 'yaw_rate_weight'",
                      timeout=10)
    describe = probe.node.create_client(DescribeParameters, "/planner_node/describe_parameters")
    setp = probe.node.create_client(SetParameters, "/planner_node/set_parameters")
    getp = probe.node.create_client(GetParameters, "/planner_node/get_parameters")
    for c in (describe, setp, getp):
        probe.wait_for_service(c)
    d = {x.name: x for x in probe.call(describe, DescribeParameters.Request(
        names=["w_heading", "depth", "period", "metric", "library_file"])).descriptors}
    assert not d["w_heading"].read_only and d["w_heading"].floating_point_range[0].to_value == 1e6
    assert d["depth"].integer_range[0].from_value == 1 and d["depth"].integer_range[0].to_value == 5
    assert d["period"].read_only and d["period"].floating_point_range[0].from_value == 0.05
    # library_file is live: setting it loads a new or fixed file (issue 23.10)
    assert "euclidean" in d["metric"].description and not d["library_file"].read_only

    # a live weight changes; the new value is used and logged
    r = probe.call(setp, SetParameters.Request(parameters=[_double("w_heading", 150.0)])).results[0]
    assert r.successful, r.reason
    got = probe.call(getp, GetParameters.Request(names=["w_heading"])).values[0].double_value
    assert got == 150.0
    node.wait_for_log(r"parameters changed: w_heading=150\.0", timeout=5)
    # out of range, wrong choice, read-only: refused with a reason, value unchanged
    for param, words in [(_double("w_heading", -1.0), "out of range"), (_integer("depth", 9), "out of range"),
                         (_double("period", 1.0), "read-only"),
                         (ParameterMsg(name="path_type", value=ParameterValue(
                             type=ParameterType.PARAMETER_STRING, string_value="spiral")), "not one of")]:
        r = probe.call(setp, SetParameters.Request(parameters=[param])).results[0]
        assert not r.successful and words in r.reason.lower().replace("read only", "read-only"), r.reason
    assert probe.call(getp, GetParameters.Request(names=["w_heading"])).values[0].double_value == 150.0
    # a cross-check: waypoints without a file is refused as a whole
    r = probe.call(setp, SetParameters.Request(parameters=[ParameterMsg(name="path_type", value=ParameterValue(
        type=ParameterType.PARAMETER_STRING, string_value="waypoints"))])).results[0]
    assert not r.successful and "waypoint_file" in r.reason
    assert node.running()
    assert node.stop() == 0 and node.stopped_cleanly


def test_use_sim_time_without_clock_is_reported(launch, probe, library):
    node = launch("planner_node", params={"library_file": str(library), "use_sim_time": True})
    diags = []
    probe.node.create_subscription(DiagnosticArray, "/diagnostics", diags.append, QOS)
    node.wait_for_log("following a line path", timeout=60)
    node.wait_for_log(r"use_sim_time is true but no /clock message has arrived", timeout=8)
    probe.spin_until(lambda: any("no /clock" in s.message for d in diags for s in d.status), 5,
                     "a diagnostics WARN about the missing clock")
    # a clock publisher brings it back
    clock_pub = probe.node.create_publisher(Clock, "/clock", 10)
    for i in range(40):
        clock_pub.publish(Clock(clock=_time(100.0 + 0.1 * i)))
        probe.spin_for(0.05)
    node.wait_for_log(r"/clock is arriving again", timeout=5)
    assert node.stop() == 0


def _time(t):
    from builtin_interfaces.msg import Time
    sec = math.floor(t)
    return Time(sec=int(sec), nanosec=int(round((t - sec) * 1e9)))


@pytest.mark.parametrize("publish_clock", [False, True])
def test_sim_stamps_stay_monotonic_across_reset(launch, probe, publish_clock):
    sim = launch("sim_node", params={"publish_clock": publish_clock, "real_time_factor": 2.0})
    odom, clock = [], []
    probe.node.create_subscription(Odometry, "/frog/sim/odom", odom.append, QOS)
    probe.node.create_subscription(Clock, "/clock", clock.append, QOS)
    probe.wait_for_topic("/frog/sim/odom", timeout=120)
    probe.spin_until(lambda: len(odom) > 50, 30, "odometry")
    reset = probe.node.create_client(Trigger, "/sim_node/reset")
    probe.wait_for_service(reset)
    before = _stamp(odom[-1])
    assert probe.call(reset, Trigger.Request()).success
    n = len(odom)
    probe.spin_until(lambda: len(odom) > n + 50, 30, "odometry after the reset")
    stamps = [_stamp(m) for m in odom]
    assert all(b > a for a, b in zip(stamps, stamps[1:])), "odometry stamps went backwards"
    assert _stamp(odom[-1]) > before
    if publish_clock:
        ticks = [c.clock.sec + c.clock.nanosec * 1e-9 for c in clock]
        assert len(ticks) > 50 and all(b >= a for a, b in zip(ticks, ticks[1:]))
        # stamps are simulated time: about 2 s per wall second, starting near zero
        assert stamps[0] < 60.0
    assert sim.stop() == 0 and sim.stopped_cleanly


def test_sim_real_time_factor_is_live(launch, probe):
    sim = launch("sim_node", params={"publish_clock": True, "real_time_factor": 1.0})
    clock = []
    probe.node.create_subscription(Clock, "/clock", clock.append, QOS)
    probe.wait_for_topic("/clock", timeout=120)
    setp = probe.node.create_client(SetParameters, "/sim_node/set_parameters")
    probe.wait_for_service(setp)

    def rate():
        clock.clear()
        probe.spin_for(2.0)
        ticks = [c.clock.sec + c.clock.nanosec * 1e-9 for c in clock]
        return (ticks[-1] - ticks[0]) / 2.0

    # slowed, not sped up: a busy machine cannot run the world at 4x (1.86 simulated s per wall s seen
    # beside two busy processes), but it can always run it at a quarter
    probe.spin_for(0.5)
    before = rate()
    r = probe.call(setp, SetParameters.Request(parameters=[_double("real_time_factor", 0.25)])).results[0]
    assert r.successful, r.reason
    probe.spin_for(0.5)
    after = rate()
    assert after < 0.4 and after < 0.5 * before, \
        f"simulated s per wall s: {before:.2f} at 1, {after:.2f} after setting 0.25"
    r = probe.call(setp, SetParameters.Request(parameters=[_double("real_time_factor", -1.0)])).results[0]
    assert not r.successful and "real_time_factor" in r.reason
    assert sim.stop() == 0


def test_every_numeric_parameter_has_a_range(launch, probe, library):
    """ros2 param describe shows a range for every numeric parameter of the frog nodes."""
    nodes = [launch("sim_node"), launch("planner_node", params={"library_file": str(library)}),
             launch("recorder", params={"output_dir": str(library.parent / "rec")})]
    from rcl_interfaces.srv import ListParameters
    for name in ("sim_node", "planner_node", "recorder"):
        lister = probe.node.create_client(ListParameters, f"/{name}/list_parameters")
        describe = probe.node.create_client(DescribeParameters, f"/{name}/describe_parameters")
        probe.wait_for_service(lister, timeout=120)
        probe.wait_for_service(describe)
        names = list(probe.call(lister, ListParameters.Request()).result.names)
        assert len(names) > 5
        unbounded = []
        for d in probe.call(describe, DescribeParameters.Request(names=names)).descriptors:
            numeric = d.type in (ParameterType.PARAMETER_DOUBLE, ParameterType.PARAMETER_INTEGER)
            if numeric and not (d.floating_point_range or d.integer_range):
                unbounded.append(d.name)
            assert d.description or d.name in ("use_sim_time", "start_type_description_service"), d.name
        assert not unbounded, f"{name}: numeric parameters without a range: {unbounded}"
    for n in nodes:
        assert n.stop() == 0
