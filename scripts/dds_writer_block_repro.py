#!/usr/bin/env python3
"""Does SIGKILLing a reader's process block a writer in another process?

A writer publishes odometry at 200 Hz (as sim_node) and measures every ``publish()``; a reader
of it that also publishes 640x480 images at 18 Hz (as camera_sim) is SIGKILLed and restarted
every --period s, with --busy busy processes loading the machine. It prints each second's
longest publish and counts the seconds in which a publish took longer than --slow. It checks
whether sim_node and bridge_node can stay blocked in ``publish`` after camera_sim's SIGKILL,
as seen once in a run of the suite under load. Transports are Fast DDS's default
unless --transports is given.

Examples (in ./dev shell)::

    python scripts/dds_writer_block_repro.py --duration 120 --busy 2                  # default (SHM + UDP)
    python scripts/dds_writer_block_repro.py --duration 120 --busy 2 --transports UDPv4
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time


def writer(duration: float) -> None:
    import rclpy
    from nav_msgs.msg import Odometry
    rclpy.init()
    node = rclpy.create_node("repro_writer")
    pub = node.create_publisher(Odometry, "odom", 10)
    msg = Odometry()
    end, report, worst = time.monotonic() + duration, time.monotonic() + 1.0, 0.0
    while time.monotonic() < end:
        t0 = time.monotonic()
        pub.publish(msg)
        worst = max(worst, time.monotonic() - t0)
        if time.monotonic() >= report:
            print(f"WORST {worst:.4f}", flush=True)
            worst, report = 0.0, time.monotonic() + 1.0
        rclpy.spin_once(node, timeout_sec=0.005)


def reader() -> None:
    import rclpy
    from nav_msgs.msg import Odometry
    from sensor_msgs.msg import Image
    rclpy.init()
    node = rclpy.create_node("repro_reader")
    node.create_subscription(Odometry, "odom", lambda _msg: None, 10)
    pub = node.create_publisher(Image, "image", 2)
    image = Image(width=640, height=480, encoding="mono8", step=640, data=bytes(640 * 480))
    node.create_timer(1 / 18, lambda: pub.publish(image))
    rclpy.spin(node)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--duration", type=float, default=120.0, help="s of writing (default 120)")
    ap.add_argument("--period", type=float, default=2.0, help="s between the reader's SIGKILLs (default 2)")
    ap.add_argument("--busy", type=int, default=2, help="busy processes loading the machine (default 2)")
    ap.add_argument("--slow", type=float, default=0.1, help="a publish longer than this counts (default 0.1 s)")
    ap.add_argument("--transports", help="FASTDDS_BUILTIN_TRANSPORTS for both processes")
    ap.add_argument("--role", choices=("writer", "reader"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.role == "writer":
        writer(args.duration)
        return 0
    if args.role == "reader":
        reader()
        return 0
    if not (args.duration > args.period > 0 and args.busy >= 0 and args.slow > 0):
        ap.error("need --duration > --period > 0, --busy >= 0 and --slow > 0")
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    from dds_restart_repro import isolated_domain
    domain, env = isolated_domain(args.transports)
    me = [sys.executable, os.path.abspath(__file__)]
    busy = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(args.busy)]
    out = subprocess.Popen(me + ["--role", "writer", "--duration", str(args.duration)], env=env,
                           stdout=subprocess.PIPE, text=True)
    kills, reader_proc = 0, None
    try:
        end = time.monotonic() + args.duration
        while time.monotonic() < end - args.period:
            reader_proc = subprocess.Popen(me + ["--role", "reader"], env=env)
            time.sleep(args.period)
            reader_proc.kill()
            reader_proc.wait()
            kills += 1
        worst = [float(line.split()[1]) for line in out.communicate(timeout=args.duration + 60)[0].splitlines()
                 if line.startswith("WORST")]
    finally:
        if reader_proc is not None and reader_proc.poll() is None:
            reader_proc.kill()
        if out.poll() is None:
            out.kill()
        for b in busy:
            b.kill()
        domain.release()
    slow = [w for w in worst if w > args.slow]
    print(f"transports {args.transports or 'default'}, {args.busy} busy, {kills} reader SIGKILLs: "
          f"{len(slow)} of {len(worst)} s had a publish over {args.slow:g} s (longest {max(worst, default=0):.3f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
