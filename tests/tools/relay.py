"""Test relay process: subscribe to a topic of a given type and republish each message.

Usage: relay.py soft_robot_interfaces/msg/Primitive /in /out
"""

import importlib
import sys

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.qos import QoSProfile, ReliabilityPolicy


def main():
    type_name, src, dst = sys.argv[1:4]
    pkg, _, name = type_name.split("/")
    msg_type = getattr(importlib.import_module(f"{pkg}.msg"), name)
    rclpy.init()
    node = rclpy.create_node("relay")
    qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
    pub = node.create_publisher(msg_type, dst, qos)
    node.create_subscription(msg_type, src, pub.publish, qos)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()


if __name__ == "__main__":
    main()
