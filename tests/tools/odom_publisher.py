"""Test publisher: Odometry at a fixed rate with content given by its sequence number.

Usage: odom_publisher.py --topic /odom --rate 1000 --count 10000 [--wait-subscribers 1]
Sequence number = pose.pose.position.x; header.stamp = wall time of publishing.
"""

import argparse
import sys
import time
from pathlib import Path

import rclpy
from nav_msgs.msg import Odometry
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

sys.path.insert(0, str(Path(__file__).parent))
from odom_content import fill_odom  # noqa: E402


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--topic", default="/odom")
    ap.add_argument("--rate", type=float, default=1000.0, help="messages per second")
    ap.add_argument("--count", type=int, default=10000, help="0 = until stopped")
    ap.add_argument("--depth", type=int, default=1000)
    ap.add_argument("--wait-subscribers", type=int, default=1)
    ap.add_argument("--linger", type=float, default=2.0, help="seconds to stay up after the last")
    args, _ = ap.parse_known_args()
    rclpy.init()
    node = rclpy.create_node("odom_publisher")
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=args.depth,
                     reliability=ReliabilityPolicy.RELIABLE)
    pub = node.create_publisher(Odometry, args.topic, qos)
    try:
        while pub.get_subscription_count() < args.wait_subscribers:
            time.sleep(0.02)
        time.sleep(0.3)  # let the reliable reader finish matching
        print(f"publishing {args.count} messages at {args.rate} Hz", flush=True)
        t0 = time.monotonic()
        seq = 0
        period = 1.0 / args.rate
        msg = Odometry()
        while args.count == 0 or seq < args.count:
            due = t0 + seq * period
            delay = due - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            fill_odom(msg, seq)
            now = time.time_ns()
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(now, 1_000_000_000)
            pub.publish(msg)
            seq += 1
        elapsed = time.monotonic() - t0
        print(f"done {seq} messages in {elapsed:.3f} s ({seq / elapsed:.1f} msg/s)", flush=True)
        time.sleep(args.linger)
    except KeyboardInterrupt:
        print(f"interrupted after {seq} messages", flush=True)
    finally:
        node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()


if __name__ == "__main__":
    main()
