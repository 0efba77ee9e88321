"""Say so when a node runs on simulated time and no ``/clock`` arrives (or it stops).

With ``use_sim_time`` and no clock publisher, ROS time stays at zero and every timer on
the node's clock silently never fires. The watch runs on the steady clock instead, so it
still ticks, and reports in the log and on ``diagnostics``.
"""

from __future__ import annotations

from rclpy.clock import Clock, ClockType

from .diagnostics import WARN, NodeDiagnostics


class SimClockWatch:
    """Steady-clock check that the node's ROS clock advances when ``use_sim_time`` is set."""

    def __init__(self, node, timeout_s: float = 3.0, period_s: float = 1.0):
        self.node = node
        self.timeout_s = timeout_s
        self.steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.last_ros_ns = node.get_clock().now().nanoseconds
        self.last_change = self.steady.now()
        self.state = "starting"      # starting -> ok | missing | stalled
        self.message, self.waited = "", 0.0
        self.diagnostics = NodeDiagnostics(node, "clock", lambda: (WARN, self.message, {
            "seconds_without_clock": f"{self.waited:.1f}"}), hardware_id=node.get_fully_qualified_name(),
            period_s=None, stamp=self._stamp)
        self.timer = node.create_timer(period_s, self.check, clock=self.steady)

    @staticmethod
    def wanted(node) -> bool:
        return node.has_parameter("use_sim_time") and bool(node.get_parameter("use_sim_time").value)

    def check(self) -> None:
        now_ros = self.node.get_clock().now().nanoseconds
        now = self.steady.now()
        if now_ros != self.last_ros_ns:
            self.last_ros_ns = now_ros
            self.last_change = now
            if self.state in ("missing", "stalled"):
                self.node.get_logger().info("/clock is arriving again (use_sim_time)")
            self.state = "ok"
            return
        waited = (now - self.last_change).nanoseconds * 1e-9
        if waited < self.timeout_s:
            return
        state = "missing" if now_ros == 0 else "stalled"
        message = ("use_sim_time is true but no /clock message has arrived for %.0f s: time stands still "
                   "and timers do not fire (start the simulator with publish_clock, or set use_sim_time "
                   "false)" % waited) if state == "missing" else (
                   "use_sim_time is true and /clock has not advanced for %.0f s (simulator paused or gone)" % waited)
        if state != self.state:
            self.node.get_logger().warn(message)
        self.state, self.message, self.waited = state, message, waited
        self.diagnostics.publish()

    def _stamp(self):
        return self.steady.now().to_msg() if self.last_ros_ns == 0 else self.node.get_clock().now().to_msg()
