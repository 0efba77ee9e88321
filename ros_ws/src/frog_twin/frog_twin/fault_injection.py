"""The twin's fault injector and observer, on the twin's watch node.

:class:`FaultInjector` turns :class:`frog_twin.core.faults.Fault` items into actions at
their simulated times: live parameters of camera_sim, robot_emulator and sim_node (their
fault hooks), the emulator's fault services, and signals to node processes through the
run's :class:`soft_robot_common.supervision.Supervisor`. :class:`RunObserver` records what
the metrics need (decisions, firings, planner states, the recorder's subscriptions) on the
watch's own subscriptions, so the record does not depend on the recorder, which is one of the
nodes under test, and feeds the run's :class:`soft_robot_common.liveness.LivenessMonitor`
with every arrival and typed diagnostics value it sees.
"""

from __future__ import annotations

import signal
import time

from frog_twin.core.faults import Observed, Resubscription, restart_windows

#: simulated s after a node's restart in which the recorder may not yet have matched its publishers
DISCOVERY_S = 3.0
#: topics whose messages the recorder must not lose while it is up (stamped, reliable)
CHECKED_TOPICS = ("/frog/primitive", "/frog/planner/status", "/frog/bridge/sent", "/frog/limb_activation")
#: PlannerStatus / TrackerState codes as the liveness section's typed values
PLANNER_STATES = ("idle", "following", "goal_reached", "waiting", "error")
TRACKER_STATES = ("searching", "tracking", "coasting", "lost", "frozen")


#: History of the watch's subscriptions: 5000 odometry messages are 2.8 min at 30 Hz.
WATCH_DEPTH = 5000


def _stamp(msg) -> float:
    return msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9


class RunObserver:
    """Subscriptions of the watch node: sim time, odometry, decisions, firings, diagnostics, tracker
    states; every arrival and diagnostics value also goes to ``monitor`` (a LivenessMonitor, or None)."""

    def __init__(self, node, monitor=None):
        from diagnostic_msgs.msg import DiagnosticArray
        from nav_msgs.msg import Odometry
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        from rosgraph_msgs.msg import Clock
        from soft_robot_interfaces.msg import LimbActivation, PlannerStatus, Primitive, TrackerState
        self.node = node
        self.monitor = monitor
        self.recorder_deaf = []         # [(sim t0, sim t1, topic)]: the recorder alive, recording nothing on topic
        self.recorder_unready = []      # [(sim t0, sim t1)]: a restarted recorder that never got ready
        self.obs = Observed()
        self.seen = {t: [] for t in CHECKED_TOPICS}
        self.sim_now = None
        self.recorder_up = []           # [(sim t0, sim t1)] with the recorder subscribed to CHECKED_TOPICS
        self.restarts = []              # sim times of node restarts (see discovery_gaps)
        self.resubscription = Resubscription(CHECKED_TOPICS)    # a restarted recorder's own subscriptions
        self._up_since = None
        self._unready_since = None      # sim time of the recorder's restart, until it is ready
        # deep: the checks need every message, and a reliable keep-last reader still drops the oldest
        # when its owner does not take them for a while (100 odometry messages are 3.3 s at 30 Hz)
        reliable = QoSProfile(depth=WATCH_DEPTH, reliability=ReliabilityPolicy.RELIABLE)
        node.create_subscription(Clock, "/clock", self._on_clock, QoSProfile(depth=1,
                                 reliability=ReliabilityPolicy.BEST_EFFORT))
        node.create_subscription(Odometry, "/frog/odom", lambda m: self.obs.odom.append(_stamp(m)), reliable)
        node.create_subscription(Primitive, "/frog/primitive", self._on_primitive, reliable)
        node.create_subscription(PlannerStatus, "/frog/planner/status", self._on_status, reliable)
        node.create_subscription(TrackerState, "/frog/tracker/state", self._on_tracker_state, reliable)
        node.create_subscription(LimbActivation, "/frog/bridge/sent",
                                 lambda m: self._arrived("/frog/bridge/sent", m), reliable)
        node.create_subscription(LimbActivation, "/frog/limb_activation", self._on_fired, reliable)
        node.create_subscription(DiagnosticArray, "/diagnostics", self._on_diagnostics, reliable)

    # -- arrivals -----------------------------------------------------------------------------
    def _tell(self, topic: str) -> None:
        if self.monitor is not None:
            self.monitor.message(topic, time.monotonic(), self.sim_now)

    def _arrived(self, topic: str, msg) -> float:
        t = _stamp(msg)
        self.seen[topic].append(t)
        self._tell(topic)
        return t

    def _on_clock(self, msg) -> None:
        t = msg.clock.sec + msg.clock.nanosec * 1e-9
        advanced = self.sim_now is None or t > self.sim_now
        self.sim_now = t
        if advanced:                    # a paused simulator publishes the same time: no heartbeat
            self._tell("/clock")

    def _on_primitive(self, msg) -> None:
        self.obs.decisions.append((self._arrived("/frog/primitive", msg), msg.name))

    def _on_status(self, msg) -> None:
        t = self._arrived("/frog/planner/status", msg)
        self.obs.status.append((t, int(msg.state)))
        if self.monitor is not None and msg.state < len(PLANNER_STATES):
            self.monitor.value("planner_node", "status", PLANNER_STATES[msg.state], time.monotonic(), self.sim_now)

    def _on_tracker_state(self, msg) -> None:
        self._tell("/frog/tracker/state")
        if self.monitor is not None and msg.state < len(TRACKER_STATES):
            self.monitor.value("tracker_node", "frame_state", TRACKER_STATES[msg.state], time.monotonic(),
                               self.sim_now)

    def _on_fired(self, msg) -> None:
        t = self._arrived("/frog/limb_activation", msg)
        if len(msg.limbs):
            self.obs.fired.append(t)

    def _on_diagnostics(self, msg) -> None:
        if self.monitor is None:
            return
        for st in msg.status:               # "<node>: <what>" (NodeDiagnostics); the values are typed
            node = st.name.split(":", 1)[0]
            self.monitor.diagnostics(node, {kv.key: kv.value for kv in st.values}, time.monotonic(), self.sim_now)

    # -- the recorder's record ----------------------------------------------------------------
    def seen_counts(self) -> dict:
        """{checked topic: messages this node saw on it so far}."""
        return {t: len(stamps) for t, stamps in self.seen.items()}

    def recorder_went_deaf(self, topic: str, heard_at) -> None:
        """The recorder recorded nothing on ``topic`` since ``heard_at`` (simulated time, or None):
        it was not up since then (it is killed and restarted next)."""
        if self.sim_now is None:
            return
        known = [t for t in (heard_at, self._up_since) if t is not None]
        since = max(known) if known else self.sim_now
        if self._up_since is not None:
            self.recorder_up.append((self._up_since, since))
            self._up_since = None
        self.recorder_deaf.append((since, self.sim_now, topic))

    def node_restarted(self, name: str) -> None:
        if self.sim_now is not None:
            self.restarts.append(self.sim_now)
            if name == "recorder":
                self._close_unready()        # its predecessor was killed or exited before it got ready
                self._unready_since = self.sim_now
                self.resubscription.restarted(self.sim_now)

    def _close_unready(self) -> None:
        if self._unready_since is not None and self.sim_now is not None:
            self.recorder_unready.append((self._unready_since, self.sim_now))
        self._unready_since = None

    def discovery_gaps(self) -> dict:
        """{topic: [(t0, t1)]}: from each restart to DISCOVERY_S after the first message seen on the topic
        after it (a restarted publisher is matched by the recorder only after discovery), and from
        each restart of the recorder to DISCOVERY_S after its new subscription to the topic."""
        own = self.resubscription.gaps(DISCOVERY_S)
        return {topic: restart_windows(self.restarts, stamps, DISCOVERY_S) + own[topic]
                for topic, stamps in self.seen.items()}

    def watch_recorder_subscriptions(self) -> None:
        """Called every poll: the recorder's subscription endpoints on the checked topics (graph)."""
        if self.sim_now is None:
            return
        for topic in CHECKED_TOPICS:
            gids = [tuple(i.endpoint_gid) for i in self.node.get_subscriptions_info_by_topic(topic)
                    if i.node_name == "recorder"]
            self.resubscription.seen(self.sim_now, topic, gids)

    def watch_recorder(self, subscribed: bool, ready: bool = True) -> None:
        """Called every poll with whether the recorder is subscribed to every checked topic, and whether
        it is ready (its typed diagnostics). Up needs both: the graph still shows a killed recorder's
        subscriptions until their lease ends, and a restarted recorder may be subscribed to a topic and
        receive nothing on it while it is not watched for deafness (it is recovering)."""
        if self.sim_now is None:
            return
        up = subscribed and ready
        if up:
            self._unready_since = None
        if up and self._up_since is None:
            self._up_since = self.sim_now
        elif not up and self._up_since is not None:
            self.recorder_up.append((self._up_since, self.sim_now))
            self._up_since = None

    def close_recorder_interval(self, recorder_running: bool) -> None:
        self._close_unready()
        if self._up_since is not None and recorder_running:
            self.recorder_up.append((self._up_since, self.sim_now))
        self._up_since = None


class FaultInjector:
    """Runs the faults' actions when the simulated clock (``sim_t`` after the planner's start) reaches them."""

    def __init__(self, node, faults, supervisor, log=print):
        self.node = node
        self.supervisor = supervisor
        self.log = log
        self.pending = []          # (sim time, wall deadline or None, description, action)
        self.done = []             # (sim time, wall time, description) of actions taken
        self._clients = {}
        self._futures = []
        self._sim_abs = 0.0         # /clock at the last tick
        self.held = set()          # nodes SIGSTOPped now (their silence is the fault's)
        self.clock_paused = False  # sim_node paused by a clock_stall (no /clock on purpose)
        for f in faults:
            self._plan(f)
        self.pending.sort(key=lambda a: a[0])

    # -- plan ---------------------------------------------------------------------------------
    def _plan(self, f) -> None:
        at, end = f.at, f.at + f.duration
        k = f.kind
        if k == "camera_freeze":
            self._at(at, f"{f.label()}: camera frozen", lambda: self._set("camera_sim", fault_freeze=True))
            self._at(end, f"{f.label()}: camera live", lambda: self._set("camera_sim", fault_freeze=False))
        elif k == "camera_stop":
            self._at(at, f"{f.label()}: camera stopped", lambda: self._set("camera_sim", fault_stopped=True))
            self._at(end, f"{f.label()}: camera running", lambda: self._set("camera_sim", fault_stopped=False))
        elif k == "occlude":
            # camera_sim's occluder runs on its node clock (simulated time): from now for the duration
            self._at(at, f"{f.label()}: tag covered", lambda: self._set(
                "camera_sim", occlusion_start_s=float(self._sim_abs), occlusion_duration_s=float(f.duration)))
        elif k == "frame_drop":
            self._at(at, f"{f.label()}: frames dropped", lambda: self._set("camera_sim", drop_probability=f.rate))
            self._at(end, f"{f.label()}: no drops", lambda: self._set("camera_sim", drop_probability=0.0))
        elif k == "ble_loss":
            self._at(at, f"{f.label()}: BLE losses", lambda: self._set("robot_emulator", loss_rate=f.rate))
            self._at(end, f"{f.label()}: BLE clean", lambda: self._set("robot_emulator", loss_rate=0.0))
        elif k == "unplug":      # the emulator stays unplugged until ~/replug (unplug_duration_s 0)
            self._at(at, f"{f.label()}: relay unplugged", lambda: self._call("robot_emulator", "unplug"))
            self._at(end, f"{f.label()}: relay plugged in", lambda: self._call("robot_emulator", "replug"))
        elif k == "emergency":
            self._at(at, f"{f.label()}: EMERGENCY", lambda: self._call("robot_emulator", "inject_emergency"))
        elif k == "kill":
            def kill():
                if not f.restart:
                    self.supervisor.release(f.target, "killed by the fault injector, not restarted")
                self.supervisor.process(f.target).send(signal.SIGKILL)
            self._at(at, f"{f.label()}: SIGKILL {f.target}", kill)
        elif k == "clock_stall":
            def pause(paused):
                self._set("sim_node", paused=paused)    # raises if it cannot: then the state is unchanged
                self.clock_paused = paused
            self._at(at, f"{f.label()}: clock paused", lambda: pause(True),
                     wall_after=(f.duration, f"{f.label()}: clock running", lambda: pause(False)))
        elif k == "sigstop":
            def stop():
                self.held.add(f.target)
                self.supervisor.process(f.target).send(signal.SIGSTOP)

            def cont():
                self.supervisor.process(f.target).send(signal.SIGCONT)
                self.held.discard(f.target)
            self._at(at, f"{f.label()}: SIGSTOP {f.target}", stop,
                     wall_after=(f.duration, f"{f.label()}: SIGCONT {f.target}", cont))

    def _at(self, t, what, action, wall_after=None) -> None:
        self.pending.append((t, None, what, action, wall_after))

    # -- run ----------------------------------------------------------------------------------
    def tick(self, sim_t: float, sim_abs: float) -> None:
        """Take every action due at ``sim_t`` (s after the planner's start; ``sim_abs`` = /clock)."""
        self._sim_abs = sim_abs
        now = time.monotonic()
        keep = []
        for t, deadline, what, action, after in self.pending:
            due = (deadline is not None and now >= deadline) or (deadline is None and sim_t >= t)
            if not due:
                keep.append((t, deadline, what, action, after))
                continue
            try:
                action()
                self.done.append((sim_abs, now, what))
                self.log(f"  fault: {what} (t = {sim_t:.1f} s)")
            except Exception as exc:        # a fault that cannot be applied is reported, the run goes on
                self.done.append((sim_abs, now, f"{what} FAILED: {exc}"))
                self.log(f"  fault: {what} FAILED: {exc}")
            if after is not None:
                wall_s, what2, action2 = after
                keep.append((t, now + wall_s, what2, action2, None))
        self.pending = keep

    def finish(self) -> None:
        """Undo what must not outlive the run (a SIGSTOPped process could not be stopped cleanly)."""
        for t, deadline, what, action, after in self.pending:
            if deadline is not None:
                try:
                    action()
                except Exception:
                    pass
        self.pending = []

    # -- actions ------------------------------------------------------------------------------
    def _client(self, kind, name: str):
        if name not in self._clients:
            self._clients[name] = self.node.create_client(kind, name)
        return self._clients[name]

    def _set(self, node_name: str, **values) -> None:
        from rcl_interfaces.srv import SetParameters
        from rclpy.parameter import Parameter
        client = self._client(SetParameters, f"/{node_name}/set_parameters")
        if not client.service_is_ready():
            raise RuntimeError(f"/{node_name}/set_parameters is not available")
        req = SetParameters.Request(parameters=[Parameter(k, value=v).to_parameter_msg() for k, v in values.items()])
        self._futures.append((f"set {values} on {node_name}", client.call_async(req)))

    def _call(self, node_name: str, service: str) -> None:
        from std_srvs.srv import Trigger
        client = self._client(Trigger, f"/{node_name}/{service}")
        if not client.service_is_ready():
            raise RuntimeError(f"/{node_name}/{service} is not available")
        self._futures.append((f"{node_name}/{service}", client.call_async(Trigger.Request())))

    def failures(self) -> list[str]:
        """Parameter sets and service calls that were refused (checked after the run)."""
        out = []
        for what, fut in self._futures:
            if not fut.done():
                out.append(f"{what}: no reply")
                continue
            res = fut.result()
            if hasattr(res, "results"):
                out += [f"{what}: {r.reason}" for r in res.results if not r.successful]
            elif hasattr(res, "success") and not res.success:
                out.append(f"{what}: {res.message}")
        return out
