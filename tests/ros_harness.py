"""System-test harness: node processes on an isolated ROS 2 domain, and a graph probe.

Process supervision (domains, :class:`NodeProcess`, ``ros_args``) is a product feature and
lives in ``soft_robot_common.processes``; this module re-exports it for the tests and adds
the rclpy-based :class:`GraphProbe` and a pty pair for serial tests.
"""

from __future__ import annotations

import os

from soft_robot_common.graph_watch import IDEMPOTENT_SERVICES, GraphWatch  # noqa: F401
from soft_robot_common.processes import (DOMAIN_RANGE, LOCK_DIR, NodeProcess, RosDomain,  # noqa: F401
                                         acquire_domain, ros_args)


class GraphProbe(GraphWatch):
    """The test's node on the test's domain (``soft_robot_common.graph_watch``, as the twins use)."""

    def __init__(self, domain: RosDomain, name: str = "test_probe"):
        super().__init__(domain, name)


def open_pty_pair():
    """A pseudo-terminal pair in raw mode: (controller fd, device path pyserial can open)."""
    import tty
    controller, device = os.openpty()
    tty.setraw(controller)
    tty.setraw(device)
    path = os.ttyname(device)
    return controller, device, path
