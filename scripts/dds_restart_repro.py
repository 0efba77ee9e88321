#!/usr/bin/env python3
"""Does a SIGKILLed and restarted reader of camera-sized images get its topics back?

A publisher sends a 640x480 mono8 image and a camera_info at 18 Hz (as camera_sim does); a
subscriber (reliable, depth 2, as tracker_node) is SIGKILLed and restarted CYCLES times,
with BUSY busy processes loading the machine. Each restart prints the time to the first
message of each topic; a topic not seen within --timeout counts as lost. The subscriber also
has a 0.5 s timer: a restart whose timer stopped firing too has a wedged executor (no callback
at all after its last first message), which is what docs/faults.md reports. Transports are Fast DDS's default unless
--transports is given.

Examples (in ./dev shell)::

    python scripts/dds_restart_repro.py --cycles 20 --busy 2                # Fast DDS default
    python scripts/dds_restart_repro.py --cycles 20 --busy 2 --transports LARGE_DATA
"""

from __future__ import annotations

import argparse
import os
import re
import select
import statistics
import subprocess
import sys
import time

IMAGE_TOPIC, INFO_TOPIC = "camera/image_raw", "camera/camera_info"


def publisher() -> None:
    import rclpy
    from rclpy.qos import QoSProfile
    from sensor_msgs.msg import CameraInfo, Image
    rclpy.init()
    node = rclpy.create_node("repro_pub")
    image_pub = node.create_publisher(Image, IMAGE_TOPIC, QoSProfile(depth=2))
    info_pub = node.create_publisher(CameraInfo, INFO_TOPIC, QoSProfile(depth=2))
    image = Image(width=640, height=480, encoding="mono8", step=640, data=bytes(640 * 480))

    def tick():
        image.header.stamp = node.get_clock().now().to_msg()
        info_pub.publish(CameraInfo(header=image.header, width=640, height=480))
        image_pub.publish(image)
    node.create_timer(1 / 18, tick)
    from rclpy.executors import ExternalShutdownException
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):     # the driver's SIGTERM at the end
        pass


def subscriber() -> None:
    t0 = time.monotonic()
    import rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import CameraInfo, Image
    rclpy.init()
    node = rclpy.create_node("repro_sub")
    qos = QoSProfile(depth=2, reliability=ReliabilityPolicy.RELIABLE)
    seen = set()

    def first(kind):
        def callback(_msg):
            if kind not in seen:
                seen.add(kind)
                print(f"FIRST {kind} {time.monotonic() - t0:.2f}", flush=True)
        return callback
    node.create_subscription(Image, IMAGE_TOPIC, first("image"), qos)
    node.create_subscription(CameraInfo, INFO_TOPIC, first("info"), qos)
    node.create_timer(0.5, lambda: print("TICK", flush=True))
    rclpy.spin(node)


def first_messages(proc: subprocess.Popen, timeout: float) -> tuple[dict, int]:
    """({topic: s to its first message}, timer ticks since the last first message) until both
    topics or ``timeout``."""
    got, ticks, deadline = {}, 0, time.monotonic() + timeout
    while time.monotonic() < deadline and len(got) < 2:
        ready, _, _ = select.select([proc.stdout], [], [], 0.2)
        if ready:
            line = proc.stdout.readline()
            ticks += line.startswith("TICK")
            m = re.match(r"FIRST (\w+) ([\d.]+)", line)
            if m:
                got[m[1]], ticks = float(m[2]), 0
    return got, ticks


def isolated_domain(transports: str | None):
    """(a free ROS domain, the environment for it) with Fast DDS's ``transports`` (None: its default)."""
    sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "ros_ws", "src", "soft_robot_common"))
    from soft_robot_common.processes import acquire_domain
    domain = acquire_domain()
    env = dict(domain.env)
    env.pop("FASTDDS_BUILTIN_TRANSPORTS", None)
    if transports:
        env["FASTDDS_BUILTIN_TRANSPORTS"] = transports
    return domain, env


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cycles", type=int, default=20, help="restarts of the subscriber (default 20)")
    ap.add_argument("--busy", type=int, default=2, help="busy processes loading the machine (default 2)")
    ap.add_argument("--timeout", type=float, default=30.0, help="s for both topics after a restart (30)")
    ap.add_argument("--transports", help="FASTDDS_BUILTIN_TRANSPORTS for both processes")
    ap.add_argument("--role", choices=("pub", "sub"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.role:
        (publisher if args.role == "pub" else subscriber)()
        return 0
    if args.cycles < 1 or args.busy < 0 or not args.timeout > 0:
        ap.error("--cycles must be >= 1, --busy >= 0 and --timeout > 0")
    domain, env = isolated_domain(args.transports)
    me = [sys.executable, os.path.abspath(__file__), "--role"]
    busy = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(args.busy)]
    pub = subprocess.Popen(me + ["pub"], env=env)
    sub = subprocess.Popen(me + ["sub"], env=env, stdout=subprocess.PIPE, text=True)
    times, lost, wedged = [], 0, 0
    try:
        first_messages(sub, args.timeout)
        for cycle in range(args.cycles):
            time.sleep(3.0)
            sub.kill()
            sub.wait()
            sub = subprocess.Popen(me + ["sub"], env=env, stdout=subprocess.PIPE, text=True)
            got, ticks = first_messages(sub, args.timeout)
            missing = sorted({"image", "info"} - set(got))
            lost += bool(missing)
            wedged += bool(missing) and ticks == 0
            if not missing:
                times.append(max(got.values()))
            print(f"restart {cycle + 1}/{args.cycles}: " + ", ".join(f"{k} {v:.2f} s" for k, v in got.items())
                  + (f"; never got {', '.join(missing)} in {args.timeout:g} s, timer fired {ticks}x"
                     if missing else ""), flush=True)
    finally:
        sub.kill()
        pub.terminate()
        pub.wait(10)
        for b in busy:
            b.kill()
        domain.release()
    median = f"{statistics.median(times):.2f} s" if times else "-"
    print(f"transports {args.transports or 'default'}, {args.busy} busy: {lost} of {args.cycles} restarts "
          f"lost a topic for {args.timeout:g} s ({wedged} with no timer callback either); median time to both "
          f"topics {median}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
