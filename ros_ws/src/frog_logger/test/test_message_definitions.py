"""ros2msg definitions: dependency closure, and decoding of real CDR bytes with them."""

import pytest

from frog_logger.core.message_definitions import (MessageDefinitionError, full_message_definition,
                                                  normalize_type_name)

FAKE = {
    ("pkg", "Outer"): "# comment\nuint8 MODE_A=1\nstd_msgs/Header header\nInner[] items\n"
                      "pkg/Inner fixed\nstring<=10 label\nfloat64[3] v\n",
    ("pkg", "Inner"): "geometry_msgs/Point p  # point\nint32 k\n",
    ("std_msgs", "Header"): "builtin_interfaces/Time stamp\nstring frame_id\n",
    ("builtin_interfaces", "Time"): "int32 sec\nuint32 nanosec\n",
    ("geometry_msgs", "Point"): "float64 x\nfloat64 y\nfloat64 z\n",
}


def test_dependency_closure_each_type_once():
    text = full_message_definition("pkg/msg/Outer", lambda p, n: FAKE.get((p, n)))
    sections = text.split("=" * 80)
    names = [s.strip().splitlines()[0] for s in sections[1:]]
    assert sorted(names) == sorted(["MSG: std_msgs/Header", "MSG: pkg/Inner",
                                    "MSG: builtin_interfaces/Time", "MSG: geometry_msgs/Point"])
    assert sections[0].startswith("# comment\nuint8 MODE_A=1")


def test_missing_dependency_names_it():
    fake = dict(FAKE)
    del fake[("geometry_msgs", "Point")]
    with pytest.raises(MessageDefinitionError, match="geometry_msgs/Point"):
        full_message_definition("pkg/Outer", lambda p, n: fake.get((p, n)))


def test_bad_type_names():
    with pytest.raises(ValueError, match="not of the form"):
        normalize_type_name("pkg/srv/Thing/Extra")
    with pytest.raises(MessageDefinitionError, match="nope/msg/Nothing"):
        full_message_definition("nope/msg/Nothing", lambda p, n: None)


def test_installed_definitions_decode_rclpy_serialised_messages():
    """Independent truth: rclpy's own CDR serialiser vs mcap_ros2's decoder + our schema."""
    rclpy_serialization = pytest.importorskip("rclpy.serialization")
    from mcap.records import Schema
    from mcap_ros2.decoder import DecoderFactory
    from nav_msgs.msg import Odometry
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

    odom = Odometry(child_frame_id="frog")
    odom.header.frame_id = "tank"
    odom.header.stamp.sec, odom.header.stamp.nanosec = 7, 9
    odom.pose.pose.position.x, odom.pose.pose.orientation.w = 0.25, 1.0
    odom.pose.covariance = [float(i) for i in range(36)]
    odom.twist.twist.angular.z = -0.5
    diag = DiagnosticArray(status=[DiagnosticStatus(level=DiagnosticStatus.WARN, name="n",
                                                    values=[KeyValue(key="k", value="v")])])
    for msg, type_name in ((odom, "nav_msgs/msg/Odometry"),
                           (diag, "diagnostic_msgs/msg/DiagnosticArray")):
        text = full_message_definition(type_name)
        schema = Schema(id=1, name=type_name, encoding="ros2msg", data=text.encode())
        decode = DecoderFactory().decoder_for("cdr", schema)
        out = decode(rclpy_serialization.serialize_message(msg))
        if type_name.endswith("Odometry"):
            assert out.header.frame_id == "tank" and out.child_frame_id == "frog"
            assert (out.header.stamp.sec, out.header.stamp.nanosec) == (7, 9)
            assert out.pose.pose.position.x == 0.25 and out.pose.pose.orientation.w == 1.0
            assert list(out.pose.covariance) == list(range(36))
            assert out.twist.twist.angular.z == -0.5
        else:
            s = out.status[0]
            assert (s.level, s.name, s.values[0].key, s.values[0].value) == (1, "n", "k", "v")
