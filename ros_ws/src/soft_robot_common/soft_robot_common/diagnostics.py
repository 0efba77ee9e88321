"""A node's health on ``diagnostics`` (diagnostic_msgs/DiagnosticArray), once a second.

``NodeDiagnostics(node, "serial link", report)`` publishes one DiagnosticStatus named
``"<node name>: serial link"`` whose level, message and values come from ``report()``,
which returns ``(level, message, {key: value})`` with ``level`` one of :data:`OK`,
:data:`WARN`, :data:`ERROR`. The message says what the node waits for when it is not OK;
it is for people. Programs read the values, whose keys are typed: a node that can be at
work or not yet (a camera model still missing, a link not open) says so in ``ready``
(``true``/``false``), and every status carries the node's ``pid``, so a supervisor tells a
restarted process's word from its predecessor's. The timer runs on the steady clock (a node
on ``/clock`` still reports when simulated time stops); the stamp is the node's clock.
:meth:`NodeDiagnostics.publish` also says a change at once, between the ticks.
"""

from __future__ import annotations

import os
from typing import Callable

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.clock import Clock, ClockType

OK, WARN, ERROR = DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR


class NodeDiagnostics:
    """Publishes ``report()`` on the node's relative ``diagnostics`` topic every ``period_s``."""

    def __init__(self, node, what: str, report: Callable[[], tuple], hardware_id: str = "",
                 period_s: float | None = 1.0, stamp: Callable[[], object] | None = None):
        self.node = node
        self.stamp = stamp or (lambda: node.get_clock().now().to_msg())    # a simulator stamps with its world
        self.what = what
        self.report = report
        self.hardware_id = hardware_id or node.get_name()
        self.pub = node.create_publisher(DiagnosticArray, "diagnostics", 10)
        self.timer = None if period_s is None else node.create_timer(      # None: on publish() only
            period_s, self.publish, clock=Clock(clock_type=ClockType.STEADY_TIME))

    def publish(self) -> None:
        try:
            level, message, values = self.report()
        except Exception as exc:       # a report must never take the node down
            level, message, values = ERROR, f"diagnostics failed: {exc!r}", {}
        if isinstance(level, int):      # a core's plain 0/1/2 (OK/WARN/ERROR)
            level = bytes([level])
        status = DiagnosticStatus(name=f"{self.node.get_name()}: {self.what}", hardware_id=self.hardware_id,
                                  level=level, message=message)
        values = {**values, "pid": os.getpid()}
        status.values = [KeyValue(key=str(k), value=_text(v)) for k, v in values.items()]
        msg = DiagnosticArray(status=[status])
        msg.header.stamp = self.stamp()
        self.pub.publish(msg)


def _text(value) -> str:
    """A diagnostics value as text: floats to 3 significant digits, booleans as true/false."""
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, float):
        return f"{value:.3g}"
    return str(value)
