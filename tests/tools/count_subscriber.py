"""Baseline subscriber: deserialises and counts Odometry messages; prints the count at exit.

The rclpy executor's own ceiling, for comparing the recorder against in bench/.
"""

import signal
import sys

import rclpy
from nav_msgs.msg import Odometry
from rclpy.executors import ExternalShutdownException
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions


def main():
    topic = sys.argv[1] if len(sys.argv) > 1 else "/odom"
    signal.signal(signal.SIGINT, signal.default_int_handler)
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node("count_subscriber")
    count = [0]

    def on_msg(msg):
        count[0] += 1
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000,
                     reliability=ReliabilityPolicy.RELIABLE)
    node.create_subscription(Odometry, topic, on_msg, qos)
    node.create_timer(0.1, lambda: None)  # wake the executor so SIGINT is handled
    print("subscribed", flush=True)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        print(f"received {count[0]}", flush=True)
        node.destroy_node()
        rclpy.shutdown()


if __name__ == "__main__":
    main()
