"""The common rule for incoming messages: finite floats, a stamp, bounded arrays."""

from nav_msgs.msg import Odometry
from sensor_msgs.msg import Image, JointState
from soft_robot_common import message_problem


def test_the_first_bad_field_is_named():
    m = Odometry()
    assert message_problem(m, now_ns=5_000_000_000) == "header.stamp is zero (unstamped)"
    assert message_problem(m, now_ns=0) is None          # the start of simulated time
    m.header.stamp.sec = 3
    m.pose.covariance[7] = float("inf")
    assert message_problem(m) == "pose.covariance[7] is inf (not finite)"
    m.pose.covariance[7] = 0.0
    m.twist.twist.angular.z = float("nan")
    assert message_problem(m) == "twist.twist.angular.z is nan (not finite)"


def test_arrays_are_bounded_but_pixels_are_not():
    j = JointState(position=[0.0] * 200_000)
    assert message_problem(j, stamped=False) == "position has 200000 elements (at most 100000)"
    j.position = [1.0, float("-inf")]
    assert message_problem(j, stamped=False) == "position[1] is -inf (not finite)"
    img = Image(data=bytes(1_000_000))
    img.header.stamp.sec = 1
    assert message_problem(img) is None
