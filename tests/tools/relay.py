"""Test relay process: subscribe to a topic of a given type and republish each message.

Usage: relay.py soft_robot_interfaces/msg/Primitive /in /out

It stops through the project's ``run_node``: rclpy's own SIGINT handler shuts the context
down under a spinning executor, which then fails to build its wait set now and then (exit 1
from a clean stop, seen on a loaded machine).
"""

import importlib
import sys

from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from soft_robot_common.node_main import run_node


def main():
    type_name, src, dst = sys.argv[1:4]
    pkg, _, name = type_name.split("/")
    msg_type = getattr(importlib.import_module(f"{pkg}.msg"), name)

    class Relay(Node):
        NODE_NAME = "relay"

        def __init__(self):
            super().__init__("relay")
            qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
            pub = self.create_publisher(msg_type, dst, qos)
            self.create_subscription(msg_type, src, pub.publish, qos)
    sys.exit(run_node(Relay))


if __name__ == "__main__":
    main()
