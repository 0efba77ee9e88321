"""Conversions between the planner's plain values and ROS messages (no algorithms)."""
from __future__ import annotations

from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Path as PathMsg
from rclpy.time import Time

from frog_common.se2 import set_yaw


def seconds(stamp) -> float:
    """A builtin_interfaces/Time as seconds (0.0 when unset)."""
    return stamp.sec + stamp.nanosec * 1e-9


def to_time(t: float, clock) -> Time:
    """Seconds on ``clock``'s time base as an rclpy Time of that clock's type."""
    return Time(nanoseconds=round(t * 1e9), clock_type=clock.clock_type)


def path_message(path, frame: str, stamp) -> PathMsg:
    """nav_msgs/Path of a :class:`frog_planner.core.paths.Path`: its points with their tangent headings."""
    msg = PathMsg()
    msg.header.stamp, msg.header.frame_id = stamp, frame
    for (x, y), h in zip(path.points, path.tangent_headings):
        ps = PoseStamped()
        ps.header = msg.header
        ps.pose.position.x, ps.pose.position.y = float(x), float(y)
        set_yaw(ps.pose.orientation, float(h))
        msg.poses.append(ps)
    return msg
