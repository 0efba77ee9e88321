"""Deterministic Odometry content from a sequence number, shared by publisher and tests."""

import math


def odom_fields(seq: int) -> dict:
    """Field values the test publisher puts into message ``seq`` (SI units)."""
    return {
        "header.frame_id": "tank",
        "child_frame_id": "frog",
        "pose.pose.position.x": float(seq),
        "pose.pose.position.y": 0.5 * seq,
        "pose.pose.position.z": -1e-3 * seq,
        "pose.pose.orientation.z": math.sin(0.5 * seq * 1e-3),
        "pose.pose.orientation.w": math.cos(0.5 * seq * 1e-3),
        "twist.twist.linear.x": 1e-3 * seq,
        "twist.twist.angular.z": -2e-3 * seq,
        "pose.covariance": [seq + i for i in range(36)],
    }


def fill_odom(msg, seq: int):
    f = odom_fields(seq)
    msg.header.frame_id = f["header.frame_id"]
    msg.child_frame_id = f["child_frame_id"]
    p = msg.pose.pose
    p.position.x, p.position.y, p.position.z = (f["pose.pose.position.x"],
                                                f["pose.pose.position.y"],
                                                f["pose.pose.position.z"])
    p.orientation.z, p.orientation.w = f["pose.pose.orientation.z"], f["pose.pose.orientation.w"]
    msg.twist.twist.linear.x = f["twist.twist.linear.x"]
    msg.twist.twist.angular.z = f["twist.twist.angular.z"]
    msg.pose.covariance = [float(c) for c in f["pose.covariance"]]
    return msg


def read_field(msg, dotted: str):
    for part in dotted.split("."):
        msg = getattr(msg, part)
    return msg
