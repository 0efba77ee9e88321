"""A node's health on ``diagnostics`` (diagnostic_msgs/DiagnosticArray), once a second.

``NodeDiagnostics(node, "serial link", report)`` publishes one DiagnosticStatus named
``"<node name>: serial link"`` whose level, message and values come from ``report()``,
which returns ``(level, message, {key: value})`` with ``level`` one of :data:`OK`,
:data:`WARN`, :data:`ERROR`. The message says what the node waits for when it is not OK.
The timer runs on the steady clock (a node on ``/clock`` still reports when simulated time
stops); the stamp is the node's clock.
"""

from __future__ import annotations

from typing import Callable

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.clock import Clock, ClockType

OK, WARN, ERROR = DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR


class NodeDiagnostics:
    """Publishes ``report()`` on the node's relative ``diagnostics`` topic every ``period_s``."""

    def __init__(self, node, what: str, report: Callable[[], tuple], hardware_id: str = "",
                 period_s: float = 1.0):
        self.node = node
        self.what = what
        self.report = report
        self.hardware_id = hardware_id or node.get_name()
        self.pub = node.create_publisher(DiagnosticArray, "diagnostics", 10)
        self.timer = node.create_timer(period_s, self.publish, clock=Clock(clock_type=ClockType.STEADY_TIME))

    def publish(self) -> None:
        try:
            level, message, values = self.report()
        except Exception as exc:       # a report must never take the node down
            level, message, values = ERROR, f"diagnostics failed: {exc!r}", {}
        status = DiagnosticStatus(name=f"{self.node.get_name()}: {self.what}", hardware_id=self.hardware_id,
                                  level=level, message=message)
        status.values = [KeyValue(key=str(k), value=f"{v:.3g}" if isinstance(v, float) else str(v))
                         for k, v in values.items()]
        msg = DiagnosticArray(status=[status])
        msg.header.stamp = self.node.get_clock().now().to_msg()
        self.pub.publish(msg)
