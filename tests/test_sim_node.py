"""sim_node as a real process: publishes ground truth, executes primitives, rejects bad input."""

import math
import re

import pytest
from nav_msgs.msg import Odometry
from rclpy.qos import QoSProfile, ReliabilityPolicy
from visualization_msgs.msg import Marker

pytestmark = pytest.mark.system

QOS = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)


def _yaw(q):
    return 2 * math.atan2(q.z, q.w)


def _stamp(m):
    return m.header.stamp.sec + m.header.stamp.nanosec * 1e-9


def _window(probe, msgs, seconds, timeout=60.0):
    """The messages stamped within ``seconds`` from the first one (waiting until the stamps span that)."""
    probe.spin_until(lambda: msgs and _stamp(msgs[-1]) >= _stamp(msgs[0]) + seconds, timeout,
                     f"{seconds} s of stamps")
    return [m for m in msgs if _stamp(m) < _stamp(msgs[0]) + seconds]


def test_publishes_odometry_and_shape_at_rate(launch, probe):
    sim = launch("sim_node", params={"odom_rate_hz": 50.0, "shape_rate_hz": 10.0,
                                     "initial_x": 0.2, "initial_y": -0.1,
                                     "initial_heading": 0.5, "publish_clock": True})   # stamps: simulated time
    odom, shape = [], []
    probe.node.create_subscription(Odometry, "/frog/sim/odom", odom.append, QOS)
    probe.node.create_subscription(Marker, "/frog/sim/shape", shape.append, QOS)
    probe.wait_for_topic("/frog/sim/odom", timeout=120)
    sim.wait_for_log("simulating the frog", timeout=120)
    odom.clear()
    shape.clear()
    # 50 Hz in simulated time: about 150 messages in 3 s, counted on the simulated-time stamps
    # (on the wall clock, arrivals or system-time stamps, a loaded sim catching up after a stall
    # put 172 in 3 s)
    odom[:] = _window(probe, odom, 3.0)
    shape[:] = _window(probe, shape, 3.0)
    assert 100 <= len(odom) <= 170, len(odom)
    assert 20 <= len(shape) <= 35, len(shape)
    m = odom[-1]
    assert (m.header.frame_id, m.child_frame_id) == ("tank", "frog")
    # at rest with no actuation: stays at the initial pose
    assert m.pose.pose.position.x == pytest.approx(0.2, abs=1e-6)
    assert m.pose.pose.position.y == pytest.approx(-0.1, abs=1e-6)
    assert _yaw(m.pose.pose.orientation) == pytest.approx(0.5, abs=1e-6)
    stamps = [o.header.stamp.sec + o.header.stamp.nanosec * 1e-9 for o in odom]
    assert all(b > a for a, b in zip(stamps, stamps[1:]))
    s = shape[-1]
    assert s.type == Marker.LINE_LIST and len(s.points) % 2 == 0 and len(s.points) > 200
    assert sim.stop() == 0 and sim.stopped_cleanly


def test_primitive_moves_the_frog_and_bad_commands_are_rejected(launch, probe):
    from soft_robot_interfaces.msg import LimbActivation, Primitive
    sim = launch("sim_node", params={"real_time_factor": 2.0, "publish_clock": True})   # stamps: simulated time
    odom = []
    probe.node.create_subscription(Odometry, "/frog/sim/odom", odom.append, QOS)
    prim_pub = probe.node.create_publisher(Primitive, "/frog/primitive", QOS)
    limb_pub = probe.node.create_publisher(LimbActivation, "/frog/limb_activation", QOS)
    probe.wait_for_topic("/frog/sim/odom", timeout=120)
    sim.wait_for_log("simulating the frog", timeout=120)
    probe.wait_matched(prim_pub)
    probe.wait_matched(limb_pub)

    # a name that contradicts the id is rejected
    prim_pub.publish(Primitive(id=1, name="C"))
    sim.wait_for_log(r"rejected primitive: id 1 is 'B'", timeout=10)
    # out-of-range limb ids are rejected; the range-checked message type cannot even carry
    # an id > 255, so use 7
    limb_pub.publish(LimbActivation(limbs=[0, 7], pulse_duration=0.08))
    sim.wait_for_log(r"rejected limb activation \[0, 7\]", timeout=10)
    limb_pub.publish(LimbActivation(limbs=[0], pulse_duration=float("nan")))
    sim.wait_for_log(r"rejected limb activation: pulse_duration", timeout=10)
    assert sim.running()
    probe.spin_until(lambda: odom, 30, "odometry")
    start, t_start = odom[-1].pose.pose.position, _stamp(odom[-1])

    prim_pub.publish(Primitive(id=Primitive.ID_B, name="B"))   # all four limbs: forward
    probe.spin_until(lambda: _stamp(odom[-1]) >= t_start + 4.0, 60, "4 simulated seconds")
    end = odom[-1].pose.pose.position
    moved = math.hypot(end.x - start.x, end.y - start.y)
    assert moved > 2e-3, f"primitive B moved the frog only {moved * 1e3:.2f} mm"
    assert end.x > start.x, "primitive B should move the frog forward (+x at heading 0)"
    assert sim.stop() == 0


def test_command_delay_fires_a_primitive_after_its_stamp_in_simulated_time(launch, probe):
    """command_delay_s 0.8: a primitive stamped t fires at simulated t + 0.8 whatever its arrival (the
    frog stays exactly at rest before, swims after); one stamped more than 0.8 s ago fires at once and is
    counted late."""
    from diagnostic_msgs.msg import DiagnosticArray
    from soft_robot_interfaces.msg import Primitive
    sim = launch("sim_node", params={"real_time_factor": 0.5, "publish_clock": True, "command_delay_s": 0.8})
    odom, diags = [], []
    probe.node.create_subscription(Odometry, "/frog/sim/odom", odom.append, QOS)
    probe.node.create_subscription(DiagnosticArray, "/diagnostics", diags.append, 10)
    prim_pub = probe.node.create_publisher(Primitive, "/frog/primitive", QOS)
    probe.wait_for_topic("/frog/sim/odom", timeout=120)
    sim.wait_for_log("simulating the frog", timeout=120)
    probe.wait_matched(prim_pub)
    probe.spin_until(lambda: odom, 30, "odometry")
    last = odom[-1]
    t0 = _stamp(last)
    msg = Primitive(id=Primitive.ID_B, name="B")
    msg.header.stamp = last.header.stamp
    prim_pub.publish(msg)
    probe.spin_until(lambda: _stamp(odom[-1]) >= t0 + 1.6, 60, "1.6 simulated seconds")
    speed = [(_stamp(m) - t0, math.hypot(m.twist.twist.linear.x, m.twist.twist.linear.y)) for m in odom
             if _stamp(m) >= t0]
    assert max(v for t, v in speed if t < 0.8 - 1e-6) < 1e-9, "the frog moved before stamp + command_delay_s"
    assert max(v for t, v in speed if t > 1.2) > 5e-3, "primitive B did not fire 0.8 s after its stamp"
    late = Primitive(id=Primitive.ID_B, name="B")
    late.header.stamp.nanosec = 1_000_000          # 1 ms: long before now (a zero stamp means "now")
    prim_pub.publish(late)
    probe.spin_until(lambda: any(kv.key == "late_commands" and kv.value == "1" for d in diags for s in d.status
                                 for kv in s.values), 30, "late_commands 1 in the diagnostics")
    assert sim.stop() == 0


def test_invalid_parameters_exit_with_message(launch):
    sim = launch("sim_node", params={"gait_phase_offset": 1.5})
    assert sim.wait(120) == 2
    assert "gait_phase_offset" in sim.log_text()
    sim = launch("sim_node", params={"model.egain_vol_pct": 33.0, "gait_frequency_hz": 1.0})
    assert sim.wait(120) == 2
    assert "fatal configuration error" in sim.log_text()


def test_true_pose_on_tf(launch, probe):
    """tank -> frog_true on tf carries the same pose as the odometry."""
    from tf2_msgs.msg import TFMessage
    sim = launch("sim_node", params={"initial_x": 0.3, "initial_heading": 1.0})
    tfs, odom = [], []
    probe.node.create_subscription(TFMessage, "/tf", tfs.append, QOS)
    probe.node.create_subscription(Odometry, "/frog/sim/odom", odom.append, QOS)
    probe.spin_until(lambda: len(tfs) > 5 and odom, 120, "tf and odometry")
    t = tfs[-1].transforms[0]
    assert (t.header.frame_id, t.child_frame_id) == ("tank", "frog_true")
    assert t.transform.translation.x == pytest.approx(0.3, abs=1e-3)
    assert _yaw(t.transform.rotation) == pytest.approx(1.0, abs=1e-3)
    assert sim.stop() == 0


def test_odom_alias_as_a_turned_tag_reports_it(launch, probe):
    """odom_alias_yaw: the alias is the truth seen in a frame turned by the yaw on the body (heading + yaw,
    the body twist rotated into that frame, the position unchanged), stamp by stamp."""
    yaw = 0.3
    sim = launch("sim_node", params={"odom_alias_topic": "frog/odom", "odom_alias_yaw": yaw, "initial_heading": 0.5,
                                     "gait_frequency_hz": 1.0, "publish_clock": True})
    truth, alias = {}, {}
    probe.node.create_subscription(Odometry, "/frog/sim/odom", lambda m: truth.setdefault(_stamp(m), m), QOS)
    probe.node.create_subscription(Odometry, "/frog/odom", lambda m: alias.setdefault(_stamp(m), m), QOS)
    # swimming (a twist to rotate): 2 s of simulated time in both
    probe.spin_until(lambda: len(set(truth) & set(alias)) > 100, 120, "odometry on both topics")
    both = sorted(set(truth) & set(alias))
    moving = 0
    for t in both:
        a, b = truth[t], alias[t]
        assert (b.pose.pose.position.x, b.pose.pose.position.y) == (a.pose.pose.position.x, a.pose.pose.position.y)
        assert math.remainder(_yaw(b.pose.pose.orientation) - _yaw(a.pose.pose.orientation) - yaw, 2 * math.pi) \
            == pytest.approx(0.0, abs=1e-9)
        u, v = a.twist.twist.linear.x, a.twist.twist.linear.y
        # the same velocity vector in the world: R(heading) (u, v) = R(heading + yaw) (u', v')
        assert b.twist.twist.linear.x == pytest.approx(math.cos(yaw) * u + math.sin(yaw) * v, abs=1e-12)
        assert b.twist.twist.linear.y == pytest.approx(-math.sin(yaw) * u + math.cos(yaw) * v, abs=1e-12)
        assert b.twist.twist.angular.z == a.twist.twist.angular.z
        moving += math.hypot(u, v) > 1e-3
    assert moving > 10, "the gait never moved the frog"
    assert sim.stop() == 0


def test_yaw_disturbance_turns_a_swimming_frog(launch, probe):
    """yaw_disturbance_sd: the tank's slowly varying torque turns a frog swimming the symmetric gait (which
    alone keeps its heading to round-off); before the first firing the frog stays put."""
    sim = launch("sim_node", params={"yaw_disturbance_sd": 2e-4, "yaw_disturbance_tau_s": 5.0, "seed": 1,
                                     "initial_heading": 0.5, "gait_frequency_hz": 1.0, "publish_clock": True})
    odom = []
    probe.node.create_subscription(Odometry, "/frog/sim/odom", odom.append, QOS)
    probe.spin_until(lambda: odom and _stamp(odom[-1]) > 4.0, 120, "4 s of simulated odometry")
    turned = [abs(math.remainder(_yaw(m.pose.pose.orientation) - 0.5, 2 * math.pi)) for m in odom]
    assert max(turned) > math.radians(1.0), max(turned)
    assert sim.stop() == 0


def test_paused_stalls_the_simulation_and_clock_then_continues(launch, probe):
    """paused (the fault injector's clock stall): no /clock, odometry or simulation while true; afterwards the
    time continues from where it stopped (no jump to catch up)."""
    import time
    from diagnostic_msgs.msg import DiagnosticArray
    from rcl_interfaces.msg import Parameter as ParameterMsg
    from rcl_interfaces.msg import ParameterType, ParameterValue
    from rcl_interfaces.srv import SetParameters
    from rosgraph_msgs.msg import Clock
    sim = launch("sim_node", params={"publish_clock": True, "gait_frequency_hz": 1.0})
    clock, odom, diags = [], [], []
    probe.node.create_subscription(Clock, "/clock", lambda m: clock.append((time.monotonic(), _t(m.clock))), 10)
    probe.node.create_subscription(Odometry, "/frog/sim/odom", odom.append, QOS)
    probe.node.create_subscription(DiagnosticArray, "/diagnostics", diags.append, QOS)
    setter = probe.node.create_client(SetParameters, "/sim_node/set_parameters")
    probe.wait_for_service(setter, timeout=120)

    def set_paused(value):
        p = ParameterMsg(name="paused", value=ParameterValue(type=ParameterType.PARAMETER_BOOL, bool_value=value))
        assert probe.call(setter, SetParameters.Request(parameters=[p])).results[0].successful

    def sim_status():
        return [{kv.key: kv.value for kv in s.values} | {"message": s.message, "level": ord(s.level)}
                for d in diags for s in d.status if "simulation" in s.name]
    probe.spin_until(lambda: clock and odom and clock[-1][1] > 1.0, 120, "1 s of simulated time and odometry")
    set_paused(True)
    paused_at = float(sim.wait_for_log(r"paused at simulated time (\d+\.\d+) s", timeout=10).group(1))
    # two diagnostics (a wall second apart) both paused, with the same simulated time and step count
    seen = len(sim_status())
    probe.spin_until(lambda: len([s for s in sim_status()[seen:] if s["paused"] == "true"]) >= 2, 10,
                     "two paused diagnostics")
    a, b = [s for s in sim_status()[seen:] if s["paused"] == "true"][:2]
    assert a["sim_time_s"] == b["sim_time_s"] and a["steps"] == b["steps"] and b["level"] == 1
    assert "paused" in b["message"]
    assert max(t for _, t in clock) <= paused_at + 1e-6, "the clock advanced while paused"
    n_odom = len(odom)
    assert max(_t(m.header.stamp) for m in odom) <= paused_at + 1e-6
    set_paused(False)
    t_resume = time.monotonic()
    probe.spin_until(lambda: clock[-1][1] > paused_at + 0.5, 20, "the clock to run again")
    first = min(t for w, t in clock if w > t_resume)
    assert paused_at < first < paused_at + 0.3, "resumed from the paused time, no jump"
    assert len(odom) > n_odom and sim.running()
    assert sim.stop() == 0


def _t(stamp):
    return stamp.sec + stamp.nanosec * 1e-9


def test_a_stalled_process_continues_without_racing_to_catch_up(launch, probe):
    """A sim_node process stopped for 2 s (as one blocked in the middleware's publish for 2.5 s after
    another node was SIGKILLed, docs/faults.md): afterwards /clock goes on at the real-time factor
    from where it stood, it does not race through the lost seconds; the lag is logged and counted."""
    import os
    import signal
    import time
    from diagnostic_msgs.msg import DiagnosticArray
    from rosgraph_msgs.msg import Clock
    sim = launch("sim_node", params={"publish_clock": True, "gait_frequency_hz": 1.0, "max_lag_s": 0.5})
    clock, diags = [], []
    probe.node.create_subscription(Clock, "/clock", lambda m: clock.append((time.monotonic(), _t(m.clock))), 100)
    probe.node.create_subscription(DiagnosticArray, "/diagnostics", diags.append, QOS)
    probe.spin_until(lambda: clock and clock[-1][1] > 1.5, 120, "1.5 s of simulated time")
    logged_before = len(sim.log_text())       # a loaded machine may have made it lag already
    os.kill(sim.pid, signal.SIGSTOP)
    try:
        probe.spin_for(0.3)                     # what was under way arrives
        stood = clock[-1][1]
        time.sleep(2.0)
    finally:
        os.kill(sim.pid, signal.SIGCONT)
    t_cont = time.monotonic()
    probe.spin_until(lambda: clock[-1][0] > t_cont + 2.0, 20, "2 s of /clock after SIGCONT")
    after = [(w - t_cont, t - stood) for w, t in clock if w > t_cont]
    # in the first wall second: at most 1 simulated s and the catch-up bound (0.5 s); the old
    # pacing put about 3.3 s there (2.3 s stood, caught up at once)
    assert max(t for w, t in after if w <= 1.0) < 1.0 + 0.5 + 0.2, after[:20]
    # and it does go on at about real time
    assert 1.2 < max(t for w, t in after if w <= 2.0) < 2.0 + 0.5 + 0.2, after[-5:]

    def lags():
        log = sim.log_text()[logged_before:]
        return [float(x) for x in re.findall(r"fell (\d+\.\d+) s behind the wall clock", log)]
    deadline = time.monotonic() + 10
    while not any(lag > 1.8 for lag in lags()) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert any(1.8 < lag < 3.0 for lag in lags()), lags()      # the stall's lag
    probe.spin_until(lambda: any(kv.key == "lags_dropped" and kv.value != "0"
                                 for d in diags for s in d.status for kv in s.values), 5, "lags_dropped > 0")
    assert sim.stop() == 0
