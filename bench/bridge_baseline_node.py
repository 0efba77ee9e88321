"""Baseline for bench/bridge_latency.py: the least an rclpy process can do for the same hops.

Subscribes ``frog/primitive`` and writes ``h 1\\n`` to the device for each message (no
checks, no scheduler); reads lines from the device in a thread and publishes an Imu for
each ``Central: Q`` line straight from that thread (no framing, no validation).

    python bench/bridge_baseline_node.py DEVICE
"""

import os
import select
import sys
import threading
import tty

import rclpy
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Imu
from soft_robot_interfaces.msg import Primitive


def main():
    path = sys.argv[1]
    rclpy.init(args=sys.argv)
    node = Node("baseline_relay")
    fd = os.open(path, os.O_RDWR | os.O_NOCTTY)
    tty.setraw(fd)
    qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
    pub = node.create_publisher(Imu, "frog/imu", qos)
    node.create_subscription(Primitive, "frog/primitive", lambda msg: os.write(fd, b"h 1\n"), qos)

    def reader():
        buf = b""
        while rclpy.ok():
            if not select.select([fd], [], [], 0.2)[0]:
                continue
            buf += os.read(fd, 4096)
            *lines, buf = buf.split(b"\n")
            for line in lines:
                if line.startswith(b"Central: Q"):
                    w, x, y, z = (float(v) for v in line[10:].split())
                    m = Imu()
                    m.orientation.w, m.orientation.x, m.orientation.y, m.orientation.z = w, x, y, z
                    pub.publish(m)
    threading.Thread(target=reader, daemon=True).start()
    node.get_logger().info("baseline ready")
    try:
        rclpy.spin(node)
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()


if __name__ == "__main__":
    main()
