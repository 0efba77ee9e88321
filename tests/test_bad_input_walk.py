"""A generated walk of bad inputs through every node (issue 23, "Deliver").

For every subscription, service and action of bridge_node, sim_node, kinematics_node,
stepper_driver and planner_node, the walk takes a valid input that *would* actuate and
spoils one field at a time: NaN, +inf and -inf in every float (and in the first element of
every float array), empty and huge (100,001 elements) arrays, the largest value of every
unsigned count, and a zero stamp where the input is a state estimate (odometry; a command
with a zero stamp means "now", as ``ros2 topic pub`` sends it). After the walk it asserts
that the node is alive and answers its parameter services, that nothing was actuated (no
``h`` line on the pty, no setpoint, no G1 written, no motion, no kick chosen), and that every
spoiled input was refused (a service or goal answered with a refusal, or a refusal logged
for the input); then the same valid input is sent once and must actuate (the detector works).
Totals go to ``bad_input_walk.json`` in the test's folder and are printed.

The other seven nodes (camera_sim, tracker_node, camera_node, recorder, robot_emulator,
marlin_emulator, image_preview) are walked in one domain by ``test_walk_observing_nodes``;
for them "nothing actuated" means no non-finite output (pose, odometry, ``Central: Q`` line,
camera_info), no rendering from a non-finite pose and no preview of a refused frame; the
recorder records every bad message and its MCAP stays readable. ``test_walk_totals`` prints
one line for all the nodes walked in the run.
"""

from __future__ import annotations

import array
import json
import math
import os
import re
import time

import numpy as np
import pytest
from rclpy.action import ActionClient
from rclpy.qos import QoSProfile, ReliabilityPolicy

pytestmark = pytest.mark.system

QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
HUGE = 100_001
REFUSAL = re.compile(r"refus|reject|ignor|invalid|non-finite|must be|out of range|not finite|is nan|is inf")
MUST_REFUSE = re.compile(r"=(nan|inf|-inf)$")     # a non-finite value must be refused (and is logged)
TOTALS: dict = {}


# -- generating the variants -------------------------------------------------------------------

def _fields(msg, prefix=""):
    """(path, kind, value) of every leaf of a message instance; kind: float, floats, msgs, uint, stamp."""
    out = []
    types = type(msg).get_fields_and_field_types()
    for name, typ in types.items():
        value = getattr(msg, name)
        path = prefix + name
        if typ == "builtin_interfaces/Time":
            out.append((path, "stamp", value))
        elif isinstance(value, float):
            out.append((path, "float", value))
        elif hasattr(type(value), "get_fields_and_field_types"):
            out += _fields(value, path + ".")
        elif typ.startswith("sequence<double") or typ.startswith("double[") or typ.startswith("sequence<float"):
            out.append((path, "floats", value))
        elif typ.startswith("sequence<") and "/" in typ:
            out.append((path, "msgs", typ[len("sequence<"):].rstrip(">").split(",")[0]))
        elif typ.startswith("sequence<uint8") or typ.startswith("sequence<octet"):
            out.append((path, "bytes", value))
        elif typ in ("uint8", "uint16", "uint32", "uint64", "octet"):
            out.append((path, "uint", typ))
    return out


def _set(msg, path, value):
    *parents, leaf = path.split(".")
    obj = msg
    for p in parents:
        obj = getattr(obj, p)
    setattr(obj, leaf, value)


def _get(msg, path):
    obj = msg
    for p in path.split("."):
        obj = getattr(obj, p)
    return obj


def _element_type(name):
    import importlib
    parts = name.split("/")
    pkg, cls = parts[0], parts[-1]
    return getattr(importlib.import_module(f"{pkg}.msg"), cls)


def variants(make, stamped: bool):
    """``[(label, message)]``: ``make()`` with one field spoiled per entry."""
    out = []
    for path, kind, info in _fields(make()):
        if kind == "float":
            for bad in (math.nan, math.inf, -math.inf):
                m = make()
                _set(m, path, bad)
                out.append((f"{path}={bad}", m))
        elif kind == "floats":
            n = len(info)
            for label, bad in (("nan", math.nan), ("inf", math.inf)):
                m = make()
                vals = list(_get(m, path)) or [0.0]
                vals[0] = bad
                _set(m, path, np.array(vals) if n and not isinstance(info, (list, array.array)) else vals)
                out.append((f"{path}[0]={label}", m))
            if not hasattr(info, "shape"):                 # variable length: empty and huge
                for label, vals in (("empty", []), ("huge", [0.0] * HUGE)):
                    m = make()
                    _set(m, path, vals)
                    out.append((f"{path}={label}", m))
        elif kind == "msgs":
            cls = _element_type(info)
            bad_item = cls()
            first = [p for p, k, _ in _fields(bad_item) if k == "float"]
            if first:
                _set(bad_item, first[0], math.nan)
                m = make()
                _set(m, path, [bad_item] + list(_get(m, path))[1:])
                out.append((f"{path}[0].{first[0]}=nan", m))
            for label, vals in (("empty", []), ("huge", [cls() for _ in range(HUGE)])):
                m = make()
                _set(m, path, vals)
                out.append((f"{path}={label}", m))
        elif kind == "bytes":
            for label, vals in (("empty", []), ("huge", [0] * HUGE)):
                m = make()
                _set(m, path, vals)
                out.append((f"{path}={label}", m))
        elif kind == "uint":
            m = make()
            _set(m, path, {"uint8": 255, "octet": b"\xff", "uint16": 65535, "uint32": 2**32 - 1,
                           "uint64": 2**64 - 1}[info])
            out.append((f"{path}=max", m))
        elif kind == "stamp" and stamped:
            m = make()
            _set(m, path, type(info)())
            out.append((f"{path}=0", m))
    return out


def _same_as_valid(m, make):
    """A variant identical to the valid input (e.g. an empty array that was already empty)."""
    from rclpy.serialization import serialize_message
    try:
        return serialize_message(m) == serialize_message(make())
    except Exception:
        return False


# -- the walk ---------------------------------------------------------------------------------

class Walk:
    def __init__(self, probe, node_name, proc):
        self.probe, self.node_name, self.proc = probe, node_name, proc
        self.rows = []          # (input, label, refused)
        # the node's diagnostics heard: its outputs reach the probe's subscriptions made before
        self.diagnostics(1)

    def diagnostics(self, n=1, timeout=30.0):
        """Wait for ``n`` diagnostics of the node published after this call began (1 Hz)."""
        from diagnostic_msgs.msg import DiagnosticArray
        prefix = self.node_name.lstrip("/") + ":"
        got = []
        sub = self.probe.node.create_subscription(
            DiagnosticArray, "/diagnostics",
            lambda m: got.append(m) if any(st.name.startswith(prefix) for st in m.status) else None, QOS)
        try:
            self.probe.spin_until(lambda: len(got) >= n, timeout, f"{n} diagnostics from {self.node_name}")
        finally:
            self.probe.node.destroy_subscription(sub)
        return got

    def barrier(self):
        """A parameter-service round trip: the node's executor has run the callbacks of what
        arrived before the request (subscriptions are served before services in a wake-up)."""
        from rcl_interfaces.srv import ListParameters
        client = self.probe.node.create_client(ListParameters, f"{self.node_name}/list_parameters")
        try:
            self.probe.wait_for_service(client, timeout=30)
            self.probe.call(client, ListParameters.Request(), timeout=30)
        finally:
            self.probe.node.destroy_client(client)

    def settled(self):
        """Past every effect of the walk: the executor has handled all of it (barrier) and two
        diagnostics published after that (>= 1 s of the node's own time) cover what a node does
        later on its timers (a rear pulse 80 ms after the front, the planner's next period)."""
        self.barrier()
        self.diagnostics(2)

    def topic(self, topic, msg_type, make, stamped=False, settle=0.05):
        pub = self.probe.node.create_publisher(msg_type, topic, QOS)
        self.probe.wait_matched(pub)
        for label, msg in variants(make, stamped):
            if _same_as_valid(msg, make) and not label.startswith("header.stamp"):
                continue                           # (the valid input is stamped "now" below: a zero stamp differs)
            before = len(self.proc.log_text())
            msg_stamp = getattr(msg, "header", None)
            if msg_stamp is not None and not label.startswith("header.stamp"):
                msg.header.stamp = self.probe.node.get_clock().now().to_msg()
            pub.publish(msg)
            # a non-finite value must be refused: its (first, so not rate-limited) refusal log is
            # waited for; other values may be accepted: after 1 s without a refusal logged, a
            # barrier shows the node has handled it, and the log is read once more
            must = MUST_REFUSE.search(label) is not None
            t0 = time.monotonic()
            refused = False
            while True:
                self.probe.spin_for(settle)
                if REFUSAL.search(self.proc.log_text()[before:]):
                    refused = True
                    break
                if not must and time.monotonic() - t0 > 1.0:
                    self.barrier()
                    refused = REFUSAL.search(self.proc.log_text()[before:]) is not None
                    break
                if time.monotonic() - t0 > 30.0:
                    break                          # not refused: finish() names it
            self.rows.append((topic, label, refused))
        return pub

    def service(self, name, srv_type, make):
        client = self.probe.node.create_client(srv_type, name)
        self.probe.wait_for_service(client, timeout=30)
        for label, req in variants(make, stamped=False):
            if _same_as_valid(req, make):
                continue
            res = self.probe.call(client, req, timeout=60)
            refused = (not res.success) and REFUSAL.search(res.message or "") is not None
            self.rows.append((name, label, refused))

    def action(self, name, action_type, make):
        client = ActionClient(self.probe.node, action_type, name)
        self.probe.spin_until(client.server_is_ready, 30, f"action {name}")
        for label, goal in variants(make, stamped=False):
            if _same_as_valid(goal, make):
                continue
            fut = client.send_goal_async(goal)
            self.probe.spin_until(fut.done, 60, "goal response")
            handle = fut.result()
            refused = not handle.accepted
            if handle.accepted:
                res = handle.get_result_async()
                self.probe.spin_until(res.done, 120, "goal result")
                r = res.result().result
                refused = not r.success and REFUSAL.search(r.message or "") is not None
            self.rows.append((name, label, refused))

    def alive(self):
        from rcl_interfaces.srv import ListParameters
        client = self.probe.node.create_client(ListParameters, f"{self.node_name}/list_parameters")
        self.probe.wait_for_service(client, timeout=10)
        reply = self.probe.call(client, ListParameters.Request(), timeout=10)
        return self.proc.running() and len(reply.result.names) > 0

    def finish(self, actuations: int, tmp_path, extra_inputs: int = 0):
        """Non-finite values must be refused; an empty array, a huge count or a zero stamp may
        instead be accepted as harmless (e.g. no limbs = nothing to fire, an empty initial guess
        = the default), provided nothing was actuated."""
        text = self.proc.log_text()
        accepted = [(i, label) for i, label, r in self.rows if not r]
        unrefused = [(i, label) for i, label in accepted if re.search(r"=(nan|inf|-inf)$", label)]
        fields = {(i, label.split("=")[0]) for i, label, _ in self.rows}
        TOTALS[self.node_name] = dict(inputs=len({i for i, _, _ in self.rows}) + extra_inputs, fields=len(fields),
                                      values_tried=len(self.rows), refusals=len(self.rows) - len(accepted),
                                      accepted_harmless=len(accepted) - len(unrefused), actuations=actuations,
                                      accepted=accepted)
        path = tmp_path.parent / "bad_input_walk.json"
        old = json.loads(path.read_text()) if path.exists() else {}
        old.update(TOTALS)
        path.write_text(json.dumps(old, indent=1))
        print(f"\nbad-input walk {self.node_name}: " + json.dumps(TOTALS[self.node_name]))
        assert "Traceback" not in text, text[-3000:]
        assert self.alive()
        assert actuations == 0
        assert not unrefused, unrefused


# -- the nodes -----------------------------------------------------------------------------------

def _read_pty(fd, into: bytearray):
    try:
        while True:
            chunk = os.read(fd, 65536)
            if not chunk:
                break
            into.extend(chunk)
    except (BlockingIOError, OSError):
        pass


def test_walk_bridge_node(launch, probe, serial_pair, tmp_path):
    from soft_robot_interfaces.msg import LimbActivation, Primitive
    controller, path = serial_pair
    os.set_blocking(controller, False)
    bridge = launch("bridge_node", params={"port": path, "settle_s": 0.1, "stall_timeout_s": 0.0})
    bridge.wait_for_log("link ready", timeout=30)
    wire = bytearray()
    walk = Walk(probe, "/bridge_node", bridge)

    def primitive():
        return Primitive(id=1, name="B")

    def limbs():
        return LimbActivation(limbs=[1], pulse_duration=0.08)
    walk.topic("/frog/primitive", Primitive, primitive)
    walk.topic("/frog/limb_command", LimbActivation, limbs)
    walk.settled()
    _read_pty(controller, wire)
    actuations = len(re.findall(rb"(?m)^h ", bytes(wire)))
    walk.finish(actuations, tmp_path)
    pub = probe.node.create_publisher(Primitive, "/frog/primitive", QOS)
    probe.wait_matched(pub)
    pub.publish(primitive())                                  # the detector works
    probe.spin_until(lambda: _read_pty(controller, wire) or re.search(rb"(?m)^h ", bytes(wire)), 5, "an h line")


def test_walk_sim_node(launch, probe, tmp_path):
    from nav_msgs.msg import Odometry
    from soft_robot_interfaces.msg import LimbActivation, Primitive
    sim = launch("sim_node", params={"execute_primitives": True})
    odom = []
    probe.node.create_subscription(Odometry, "/frog/sim/odom", odom.append, QOS)
    probe.wait_for_topic("/frog/sim/odom", timeout=90)
    walk = Walk(probe, "/sim_node", sim)
    walk.topic("/frog/primitive", Primitive, lambda: Primitive(id=1, name="B"))
    walk.topic("/frog/limb_activation", LimbActivation, lambda: LimbActivation(limbs=[1], pulse_duration=0.08))
    walk.settled()
    # (the probe's own subscription makes the topic visible at once: wait for sim_node's odometry)
    n = len(odom)
    probe.spin_until(lambda: len(odom) > n, 30, "odometry from sim_node after the walk")

    def speed():
        t = odom[-1].twist.twist
        return math.hypot(t.linear.x, t.linear.y) + abs(t.angular.z)
    moved = speed() > 1e-4 or not all(math.isfinite(v) for v in (odom[-1].pose.pose.position.x,))
    walk.finish(int(moved), tmp_path)
    pub = probe.node.create_publisher(Primitive, "/frog/primitive", QOS)
    probe.wait_matched(pub)
    pub.publish(Primitive(id=1, name="B"))
    probe.spin_until(lambda: speed() > 1e-3, 10, "the kick moving the frog")


def test_walk_kinematics_node(launch, probe, tmp_path):
    from geometry_msgs.msg import Point, PointStamped
    from sensor_msgs.msg import JointState
    from soft_robot_interfaces.action import FollowCurve
    from soft_robot_interfaces.srv import ForwardKinematics, SolveIk
    kin = launch("kinematics_node", params={"config_samples": 0})
    kin.wait_for_log("ready in", timeout=180)
    setpoints = []
    probe.node.create_subscription(JointState, "/finger/tendon_setpoints", setpoints.append, QOS)
    target = (0.0, 0.0, 0.0)
    walk = Walk(probe, "/kinematics_node", kin)
    fk = probe.node.create_client(ForwardKinematics, "/finger/forward_kinematics")
    probe.wait_for_service(fk, timeout=30)
    rest = probe.call(fk, ForwardKinematics.Request(actuation=[0.0, 0.0, 0.0]), timeout=60)
    target = (rest.tip.x, rest.tip.y, rest.tip.z - 0.002)

    def point():
        return PointStamped(point=Point(x=target[0], y=target[1], z=target[2]))
    walk.topic("/finger/target", PointStamped, point)
    walk.service("/finger/forward_kinematics", ForwardKinematics, lambda: ForwardKinematics.Request(
        actuation=[0.001, 0.0, 0.0]))
    walk.service("/finger/solve_ik", SolveIk, lambda: SolveIk.Request(
        target=Point(x=target[0], y=target[1], z=target[2]), initial_guess=[0.0, 0.0, 0.0]))
    walk.action("/finger/follow_curve", FollowCurve, lambda: FollowCurve.Goal(
        waypoints=[Point(x=target[0], y=target[1], z=target[2])], tolerance=0.001))
    walk.settled()
    walk.finish(len(setpoints), tmp_path)
    pub = probe.node.create_publisher(PointStamped, "/finger/target", QOS)
    probe.wait_matched(pub)
    pub.publish(point())
    probe.spin_until(lambda: setpoints, 60, "a setpoint for a valid target")


def test_walk_stepper_driver(launch, probe, tmp_path):
    from sensor_msgs.msg import JointState
    link = str(tmp_path / "marlin")
    transcript = tmp_path / "transcript.txt"
    launch("marlin_emulator", params={"port_link": link, "transcript": str(transcript)}).wait_for_log(
        "emulated Marlin board", timeout=30)
    drv = launch("stepper_driver", params={"port": link, "banner_timeout": 0.3, "reconnect_period": 0.2})
    drv.wait_for_log("board ready", timeout=30)
    walk = Walk(probe, "/stepper_driver", drv)

    def setpoint():
        return JointState(name=["cable_0", "cable_1", "cable_2"], position=[0.001, 0.0, 0.0])
    walk.topic("/finger/tendon_setpoints", JointState, setpoint)
    walk.settled()
    walk.finish(transcript.read_text().count(" G1 "), tmp_path)
    pub = probe.node.create_publisher(JointState, "/finger/tendon_setpoints", QOS)
    probe.wait_matched(pub)
    pub.publish(setpoint())
    probe.spin_until(lambda: " G1 " in transcript.read_text(), 10, "a G1 for a valid setpoint")


def test_walk_planner_node(launch, probe, library, tmp_path):
    from nav_msgs.msg import Odometry
    from soft_robot_interfaces.msg import Primitive
    planner = launch("planner_node", params={"library_file": str(library), "period": 0.3, "max_state_age_s": 60.0,
                                              "state_topic": ""})
    chosen = []
    probe.node.create_subscription(Primitive, "/frog/primitive", chosen.append, QOS)
    probe.wait_for_topic("/frog/primitive", timeout=60)
    walk = Walk(probe, "/planner_node", planner)

    def odom():
        m = Odometry()
        m.header.frame_id = "tank"
        m.pose.pose.orientation.w = 1.0
        m.twist.twist.linear.x = 0.01
        return m
    walk.topic("/frog/odom", Odometry, odom, stamped=True, settle=0.05)
    walk.settled()                                    # > 3 decision periods of 0.3 s since the walk
    walk.finish(sum(1 for p in chosen if p.id != Primitive.ID_I), tmp_path)
    pub = probe.node.create_publisher(Odometry, "/frog/odom", QOS)
    probe.wait_matched(pub)

    def kicked():
        m = odom()
        m.header.stamp = probe.node.get_clock().now().to_msg()
        pub.publish(m)
        return any(p.id != Primitive.ID_I for p in chosen)
    probe.spin_until(kicked, 10, "a kick chosen for valid odometry")


# -- the nodes that observe, render, record or emulate -----------------------------------------------

def _finite(msg) -> bool:
    from soft_robot_common.message_checks import nonfinite_field
    return nonfinite_field(msg, max_items=10**9) is None


def _no_input_node(name, inputs: int, tmp_path, probe, proc):
    """A node with no input that has a field to spoil (no subscription; Trigger services only)."""
    walk = Walk(probe, name, proc)
    walk.finish(0, tmp_path, extra_inputs=inputs)
    return walk


def test_walk_observing_nodes(launch, probe, tmp_path):
    """camera_sim, tracker_node, camera_node (a video file), recorder, robot_emulator,
    marlin_emulator and image_preview in one domain, their inputs remapped apart. Nothing
    actuated means here: no non-finite pose or odometry from the tracker, no rendering from a
    non-finite pose (numpy warnings) by camera_sim, no non-finite ``Central: Q`` line from
    robot_emulator, no preview of a refused frame, no non-finite camera_info from camera_node; the
    recorder records every bad message (recording is its answer) and its MCAP stays readable."""
    import cv2
    from geometry_msgs.msg import Point, PoseStamped
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    from nav_msgs.msg import Odometry
    from sensor_msgs.msg import CameraInfo, CompressedImage, Image
    from soft_robot_interfaces.msg import LimbActivation
    from visualization_msgs.msg import Marker

    clip = tmp_path / "clip.avi"
    w = cv2.VideoWriter(str(clip), cv2.VideoWriter_fourcc(*"MJPG"), 10, (160, 120))
    for _ in range(10):
        w.write(np.full((120, 160, 3), 40, np.uint8))
    w.release()
    emu_link, marlin_link, rec_dir = tmp_path / "robot_tty", tmp_path / "marlin", tmp_path / "rec"
    tracker = launch("tracker_node", params={"publish_tf": False})
    cam_sim = launch("camera_sim", params={"fps": 2.0, "noise_sigma": 0.0, "blur_samples": 1},
                     remap={"camera/image_raw": "/sim/camera/image_raw",
                            "camera/camera_info": "/sim/camera/camera_info"})
    cam = launch("camera_node", params={"source": str(clip), "loop": True},
                 remap={"camera/image_raw": "/vid/camera/image_raw",
                        "camera/camera_info": "/vid/camera/camera_info"})
    rec = launch("recorder", params={"output_dir": str(rec_dir), "file_prefix": "walk",
                                     "topics": ["/walk/odom", "/walk/limbs"]})
    emu = launch("robot_emulator", params={"link_path": str(emu_link), "imu_rate_hz": 20.0},
                 remap={"frog/sim/odom": "/emu/odom"})
    marlin = launch("marlin_emulator", params={"port_link": str(marlin_link)})
    preview = launch("image_preview", params={"rate_hz": 120.0},
                     remap={"camera/image_raw": "/preview/image_raw"})

    # -- tracker_node: camera_info, images, kicks; must publish no non-finite pose or odometry
    poses, odoms = [], []
    probe.node.create_subscription(PoseStamped, "/frog/pose", poses.append, QOS)
    probe.node.create_subscription(Odometry, "/frog/odom", odoms.append, QOS)
    k = [300.0, 0.0, 80.0, 0.0, 300.0, 60.0, 0.0, 0.0, 1.0]

    def info():
        return CameraInfo(width=160, height=120, distortion_model="plumb_bob", d=[0.0] * 5, k=k,
                          r=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
                          p=[300.0, 0.0, 80.0, 0.0, 0.0, 300.0, 60.0, 0.0, 0.0, 0.0, 1.0, 0.0])

    def image():
        return Image(width=160, height=120, encoding="bgr8", step=480, data=bytes(160 * 120 * 3))

    def kick():
        return LimbActivation(limbs=[1], pulse_duration=0.08)
    info_pub = probe.node.create_publisher(CameraInfo, "/camera/camera_info", QOS)
    probe.wait_matched(info_pub, timeout=60)

    def publish_info():
        m = info()
        m.header.stamp = probe.node.get_clock().now().to_msg()
        info_pub.publish(m)
    publish_info()
    tracker.wait_for_log("camera model from camera_info", timeout=30)
    walk = Walk(probe, "/tracker_node", tracker)
    walk.topic("/camera/camera_info", CameraInfo, info)
    publish_info()                                    # the valid model back before the images
    walk.barrier()
    walk.topic("/camera/image_raw", Image, image, stamped=True)
    walk.topic("/frog/bridge/sent", LimbActivation, kick, stamped=True)
    walk.settled()
    walk.finish(sum(not _finite(m) for m in poses + odoms), tmp_path)

    # -- camera_sim: odometry and shape; must not render from a non-finite pose
    walk = Walk(probe, "/camera_sim", cam_sim)

    def odom():
        m = Odometry()
        m.header.frame_id, m.child_frame_id = "tank", "frog"
        m.pose.pose.position.x, m.pose.pose.position.y = 0.1, 0.05
        m.pose.pose.orientation.w = 1.0
        m.twist.twist.linear.x = 0.01
        return m

    def shape():
        m = Marker(type=Marker.LINE_LIST, action=Marker.ADD)
        m.header.frame_id = "tank"
        m.pose.orientation.w = 1.0
        m.scale.x = 0.002
        m.color.a = 1.0
        corners = [(0.05, 0.03), (-0.05, 0.03), (-0.05, -0.03), (0.05, -0.03)]
        for a, b in zip(corners, corners[1:] + corners[:1]):
            m.points += [Point(x=0.1 + a[0], y=0.05 + a[1]), Point(x=0.1 + b[0], y=0.05 + b[1])]
        return m
    walk.topic("/frog/sim/odom", Odometry, odom, stamped=True)
    walk.topic("/frog/sim/shape", Marker, shape, stamped=True)
    walk.settled()
    walk.finish(len(re.findall(r"RuntimeWarning|invalid value", cam_sim.log_text())), tmp_path)

    # -- robot_emulator: odometry for its IMU; must write no non-finite Central: Q line
    fd = os.open(str(emu_link), os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    wire = bytearray()
    try:
        walk = Walk(probe, "/robot_emulator", emu)
        walk.topic("/emu/odom", Odometry, odom, stamped=True)
        walk.settled()
        _read_pty(fd, wire)
        q_lines = re.findall(rb"Central: Q[^\r\n]*", bytes(wire))
        walk.finish(sum(1 for q in q_lines if re.search(rb"nan|inf", q, re.I)), tmp_path,
                    extra_inputs=5)                        # its 5 Trigger services: no field to spoil
        pub = probe.node.create_publisher(Odometry, "/emu/odom", QOS)
        probe.wait_matched(pub)
        pub.publish(odom())                                # the detector works: a Q line for valid odometry
        probe.spin_until(lambda: _read_pty(fd, wire) or len(re.findall(rb"Central: Q", bytes(wire))) > len(q_lines),
                         5, "a Q line for valid odometry")
    finally:
        os.close(fd)

    # -- image_preview: frames; must not preview a refused frame
    previews = []
    probe.node.create_subscription(CompressedImage, "/camera/preview/compressed", previews.append, QOS)
    walk = Walk(probe, "/image_preview", preview)
    walk.topic("/preview/image_raw", Image, image, stamped=True)
    walk.settled()
    harmless = sum(1 for _, label, refused in walk.rows if not refused)
    walk.finish(max(0, len(previews) - harmless), tmp_path)

    # -- camera_node and marlin_emulator: no input with a field to spoil; alive, outputs finite
    infos = []
    probe.node.create_subscription(CameraInfo, "/vid/camera/camera_info", infos.append, QOS)
    probe.spin_until(lambda: infos, 30, "camera_node's camera_info")
    _no_input_node("/camera_node", 0, tmp_path, probe, cam)
    TOTALS["/camera_node"]["actuations"] = sum(not _finite(m) for m in infos)
    assert TOTALS["/camera_node"]["actuations"] == 0
    _no_input_node("/marlin_emulator", 5, tmp_path, probe, marlin)   # 5 Trigger services; G-code is on its pty

    # -- recorder: records every bad message; the MCAP stays readable
    published = {"/walk/odom": 0, "/walk/limbs": 0}
    rows = []
    for topic, typ, make in (("/walk/odom", Odometry, odom), ("/walk/limbs", LimbActivation, kick)):
        pub = probe.node.create_publisher(typ, topic, QOS)
        probe.wait_matched(pub)
        for label, m in variants(make, stamped=True):
            pub.publish(m)
            published[topic] += 1
            rows.append((topic, label))
            probe.spin_for(0.02)
    walk = Walk(probe, "/recorder", rec)

    def recorded_so_far():       # the recorder's own count, in its diagnostics
        st = next(st for m in walk.diagnostics(1) for st in m.status if st.name.startswith("recorder:"))
        return int({kv.key: kv.value for kv in st.values}["messages"])
    probe.spin_until(lambda: recorded_so_far() >= sum(published.values()), 120, "the recorder to hold every message")
    assert walk.alive()
    assert rec.stop() == 0 and rec.stopped_cleanly, rec.log_text()[-2000:]
    files = sorted(rec_dir.glob("walk_*.mcap"))
    recorded = {t: 0 for t in published}
    with open(files[0], "rb") as f:
        for _, channel, _, _ in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
            recorded[channel.topic] += 1
    TOTALS["/recorder"] = dict(inputs=2, fields=len({(t, lab.split("=")[0]) for t, lab in rows}),
                               values_tried=len(rows), refusals=0, accepted_harmless=len(rows),
                               actuations=0, recorded=recorded)
    print("\nbad-input walk /recorder: " + json.dumps(TOTALS["/recorder"]))
    assert "Traceback" not in rec.log_text()
    assert recorded == published, (recorded, published)


def test_walk_totals():
    """One line for all the nodes walked in this run (the per-node lines are printed above)."""
    if not TOTALS:
        pytest.skip("no node walked in this run")
    keys = ("inputs", "fields", "values_tried", "refusals", "accepted_harmless", "actuations")
    total = {"nodes": len(TOTALS), **{k: sum(t[k] for t in TOTALS.values()) for k in keys}}
    print(f"\nbad-input walk totals ({', '.join(sorted(TOTALS))}): " + json.dumps(total))
    assert total["actuations"] == 0
