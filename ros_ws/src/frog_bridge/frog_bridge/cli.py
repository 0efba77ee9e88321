"""``frog-bridge``: send a primitive or a limb command to bridge_node, clear an emergency.

A tool for bench tests of the robot: it publishes on the same topics as the planner
(``frog/primitive``) and on ``frog/limb_command``, and calls ``bridge_node``'s
``~/clear_emergency``. Messages carry a zero stamp (= "now" to the bridge), so the tool
works whether the bridge runs on wall or simulated time.
"""

from __future__ import annotations

import argparse
import sys
import time

from frog_common.primitives import LIMB_IDS, PRIMITIVE_NAMES, limb_label

EPILOG = """examples:
  frog-bridge primitive B                 all four limbs (front, then rear one pulse later)
  frog-bridge limbs FL BR                 one pulse of FL and BR now (also: frog-bridge limbs 0 3)
  frog-bridge clear-emergency             unlatch the bridge after the robot reported EMERGENCY
  frog-bridge --ns /frog2 primitive A     a bridge in namespace /frog2
exit codes: 0 sent, 1 no bridge answered in --timeout, 2 bad arguments.
"""


def _limb_id(text: str) -> int:
    key = text.upper()
    if key in LIMB_IDS:
        return LIMB_IDS[key]
    if key in ("0", "1", "2", "3"):
        return int(key)
    raise argparse.ArgumentTypeError(f"limb {text!r} is not one of FL FR BL BR or 0-3")


def _primitive(text: str) -> int:
    key = text.upper()
    if len(key) == 1 and key in PRIMITIVE_NAMES:
        return PRIMITIVE_NAMES.index(key)
    if key.isdigit() and int(key) < len(PRIMITIVE_NAMES):
        return int(key)
    raise argparse.ArgumentTypeError(f"primitive {text!r} is not one of A-I or 0-8")


def parse_args(argv):
    ap = argparse.ArgumentParser(prog="frog-bridge", description=__doc__, epilog=EPILOG,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--ns", default="", help="namespace of the bridge (default: root)")
    ap.add_argument("--timeout", type=float, default=10.0, help="wait this long for the bridge [s]")
    sub = ap.add_subparsers(dest="cmd", required=True)
    p = sub.add_parser("primitive", help="publish one primitive on frog/primitive")
    p.add_argument("name", type=_primitive, help="A-I (or 0-8)")
    p = sub.add_parser("limbs", help="publish one limb command on frog/limb_command")
    p.add_argument("limbs", type=_limb_id, nargs="+", help="FL FR BL BR (or 0-3)")
    sub.add_parser("clear-emergency", help="call the bridge's ~/clear_emergency")
    return ap.parse_args(argv)


def main(argv=None) -> int:
    args = parse_args(sys.argv[1:] if argv is None else argv)
    if args.cmd == "limbs" and len(set(args.limbs)) != len(args.limbs):
        print(f"frog-bridge: limbs {args.limbs} repeat an id", file=sys.stderr)
        return 2
    import rclpy
    from rclpy.duration import Duration
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from soft_robot_interfaces.msg import LimbActivation, Primitive
    from std_srvs.srv import Trigger
    rclpy.init(args=["--ros-args", "-r", f"__ns:={args.ns}"] if args.ns else None)
    node = rclpy.create_node("frog_bridge_cli")
    qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
    end = time.monotonic() + args.timeout
    try:
        if args.cmd == "clear-emergency":
            client = node.create_client(Trigger, "bridge_node/clear_emergency")
            if not client.wait_for_service(timeout_sec=args.timeout):
                print("frog-bridge: no bridge_node/clear_emergency service", file=sys.stderr)
                return 1
            future = client.call_async(Trigger.Request())
            rclpy.spin_until_future_complete(node, future, timeout_sec=max(end - time.monotonic(), 1.0))
            if not future.done():
                print("frog-bridge: no answer from bridge_node", file=sys.stderr)
                return 1
            print(future.result().message)
            return 0
        if args.cmd == "primitive":
            pub = node.create_publisher(Primitive, "frog/primitive", qos)
            msg = Primitive(id=args.name, name=PRIMITIVE_NAMES[args.name])
            what = f"primitive {msg.name}"
        else:
            pub = node.create_publisher(LimbActivation, "frog/limb_command", qos)
            msg = LimbActivation(limbs=args.limbs, pulse_duration=0.0)
            what = f"limbs {limb_label(args.limbs)}"
        while pub.get_subscription_count() == 0 and time.monotonic() < end:
            rclpy.spin_once(node, timeout_sec=0.05)
        if pub.get_subscription_count() == 0:
            print(f"frog-bridge: nobody subscribes to {pub.topic_name}", file=sys.stderr)
            return 1
        # the bridge must also have matched this writer, or it drops the sample: give discovery
        # a moment, then wait for the acknowledgement (reliable QoS) before the process exits
        rclpy.spin_once(node, timeout_sec=0.3)
        pub.publish(msg)
        if not pub.wait_for_all_acked(Duration(seconds=max(end - time.monotonic(), 1.0))):
            print(f"frog-bridge: {what} was not acknowledged by the bridge", file=sys.stderr)
            return 1
        print(f"sent {what} on {pub.topic_name}")
        return 0
    finally:
        node.destroy_node()
        rclpy.shutdown()


if __name__ == "__main__":
    sys.exit(main())
