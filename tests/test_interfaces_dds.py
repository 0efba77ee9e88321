"""Every custom message and service round-trips through DDS between two processes."""

import math
import time

import pytest
from rclpy.qos import QoSProfile, ReliabilityPolicy

pytestmark = pytest.mark.system

QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)


def _primitive():
    from soft_robot_interfaces.msg import Primitive
    m = Primitive(id=Primitive.ID_E, name="E")
    m.header.frame_id = "tank"
    m.header.stamp.sec, m.header.stamp.nanosec = 1234, 567
    return m


def _limb_activation():
    from soft_robot_interfaces.msg import LimbActivation
    m = LimbActivation(limbs=[LimbActivation.LIMB_FR, LimbActivation.LIMB_BL],
                       pulse_duration=0.08)
    m.header.stamp.sec = 42
    return m


def _planner_status():
    from geometry_msgs.msg import Pose2D
    from soft_robot_interfaces.msg import PlannerStatus
    return PlannerStatus(primitive_id=3, primitive_name="D", total_cost=12.5,
                         cost_distance=0.012, cost_heading=-0.25, cost_progress=0.7,
                         predicted_pose=Pose2D(x=0.1, y=-0.2, theta=math.pi / 3),
                         path_progress=0.3, distance_to_path=0.0125)


def _fields(msg):
    out = {}
    for name in msg.get_fields_and_field_types():
        v = getattr(msg, name)
        out[name] = _fields(v) if hasattr(v, "get_fields_and_field_types") else (
            list(v) if not isinstance(v, (str, bytes, int, float, bool)) else v)
    return out


@pytest.mark.parametrize("make", [_primitive, _limb_activation, _planner_status],
                         ids=["Primitive", "LimbActivation", "PlannerStatus"])
def test_message_round_trip(make, launch, probe):
    msg = make()
    type_name = type(msg).__module__.split(".")[0] + "/msg/" + type(msg).__name__
    relay = launch("relay.py", type_name, "/rt/in", "/rt/out")
    received = []
    pub = probe.node.create_publisher(type(msg), "/rt/in", QOS)
    probe.node.create_subscription(type(msg), "/rt/out", received.append, QOS)
    probe.wait_matched(pub)
    probe.wait_for_topic("/rt/out", timeout=20)
    # the relay's writer may not have matched the probe's reader yet: send again every 0.5 s
    # until a copy comes back (every copy must equal the message)
    sent = []

    def relayed():
        if received:
            return True
        if not sent or time.monotonic() - sent[-1] > 0.5:
            pub.publish(msg)
            sent.append(time.monotonic())
        return False
    probe.spin_until(relayed, timeout=30, what="relayed message")
    assert all(_fields(r) == _fields(msg) for r in received)
    assert relay.stop() == 0


def test_services_round_trip(launch, probe):
    from geometry_msgs.msg import Point
    from soft_robot_interfaces.srv import ForwardKinematics, SolveIk
    launch("echo_services.py")
    ik = probe.node.create_client(SolveIk, "/test/solve_ik")
    fk = probe.node.create_client(ForwardKinematics, "/test/forward_kinematics")
    probe.wait_for_service(ik, timeout=20)
    probe.wait_for_service(fk, timeout=20)

    req = SolveIk.Request(target=Point(x=0.01, y=-0.02, z=0.1), initial_guess=[0.1, 0.2, 0.3],
                          tolerance=2e-4, max_iterations=30)
    res = probe.call(ik, req)
    assert res.success and res.message == "echo"
    assert list(res.actuation) == [0.3, 0.2, 0.1]
    assert (res.reached.x, res.reached.y, res.reached.z) == (0.01, -0.02, 0.1)
    assert res.residual_error == 2e-4 and res.iterations == 31

    res = probe.call(fk, ForwardKinematics.Request(actuation=[0.5, -1.5]))
    assert res.success and res.message == "2 values"
    assert [(p.x, p.y, p.z) for p in res.marker_points] == [(0.5, 1.0, -0.5), (-1.5, -3.0, 1.5)]
    assert (res.tip.x, res.tip.y, res.tip.z) == (-1.5, -3.0, 1.5)


def test_out_of_range_fields_are_rejected():
    """ROS_PYTHON_CHECK_FIELDS=1 is set for tests: a wrapped uint8 would hide bugs."""
    from soft_robot_interfaces.msg import Primitive
    with pytest.raises(AssertionError):
        Primitive(id=300)
