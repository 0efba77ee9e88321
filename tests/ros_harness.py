"""System-test harness: node processes on an isolated ROS 2 domain, and a graph probe.

Process supervision (domains, :class:`NodeProcess`, ``ros_args``) is a product feature and
lives in ``soft_robot_common.processes``; this module re-exports it for the tests and adds
the rclpy-based :class:`GraphProbe` and a pty pair for serial tests.
"""

from __future__ import annotations

import os
import time
from typing import Callable

from soft_robot_common.processes import (DOMAIN_RANGE, LOCK_DIR, NodeProcess, RosDomain,  # noqa: F401
                                         acquire_domain, ros_args)


# Cheap requests with no side effect beyond an idempotent set: safe to re-send. (Kinematics
# queries are not re-sent: a solve can take seconds on a loaded machine, and IK warm-starts.)
IDEMPOTENT_SERVICES = {"ListParameters", "DescribeParameters", "GetParameters", "GetParameterTypes",
                       "SetParameters"}


class GraphProbe:
    """An rclpy node inside the test process, on the test's domain, to observe the graph."""

    def __init__(self, domain: RosDomain, name: str = "test_probe"):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        self._rclpy = rclpy
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain.domain_id)
        self.node = rclpy.create_node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def spin_for(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=min(0.05, max(0.0, end - time.monotonic())))

    def spin_until(self, predicate: Callable[[], bool], timeout: float, what: str = "condition"):
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if predicate():
                return time.monotonic() - (end - timeout)
            self.executor.spin_once(timeout_sec=0.05)
        if predicate():
            return timeout
        raise TimeoutError(f"{what} not reached within {timeout} s")

    def node_names(self) -> set[str]:
        return {ns.rstrip("/") + "/" + n if ns != "/" else "/" + n
                for n, ns in self.node.get_node_names_and_namespaces()}

    def wait_for_node(self, fq_name: str, timeout: float = 15.0) -> float:
        return self.spin_until(lambda: fq_name in self.node_names(), timeout,
                               f"node {fq_name} to appear")

    def wait_node_gone(self, fq_name: str, timeout: float = 15.0) -> float:
        return self.spin_until(lambda: fq_name not in self.node_names(), timeout,
                               f"node {fq_name} to leave the graph")

    def wait_for_topic(self, topic: str, timeout: float = 15.0, publishers: int = 1) -> float:
        return self.spin_until(lambda: self.node.count_publishers(topic) >= publishers,
                               timeout, f"a publisher on {topic}")

    def wait_for_subscriber(self, topic: str, timeout: float = 15.0) -> float:
        return self.spin_until(lambda: self.node.count_subscribers(topic) >= 1,
                               timeout, f"a subscriber on {topic}")

    def wait_matched(self, publisher, subscribers: int = 1, timeout: float = 30.0) -> float:
        """Wait until ``publisher`` (the probe's) has matched ``subscribers`` readers in DDS.

        The graph (:meth:`wait_for_subscriber`) shows a subscription before the probe's writer
        has matched it; a reliable, volatile message published in between is lost. The match
        count is the writer's own view: a message published after this returns is delivered.
        """
        return self.spin_until(lambda: publisher.get_subscription_count() >= subscribers, timeout,
                               f"{subscribers} matched subscriber(s) on {publisher.topic_name}")

    def wait_heard(self, msg_type, topic: str, timeout: float = 30.0, qos=10, accept=None) -> float:
        """Wait for one message on ``topic`` through a new subscription (then destroyed).

        The publishing process has then discovered this subscription, and with it every
        subscription the probe created before (Fast DDS announces a participant's endpoints in
        creation order on one reliable channel): its outputs on those topics now reach the probe.
        Use with a topic the node publishes periodically (``/diagnostics``, a status);
        ``accept(msg)`` picks that node's messages where several publish on the topic.
        """
        got = []
        sub = self.node.create_subscription(
            msg_type, topic, lambda m: got.append(m) if accept is None or accept(m) else None, qos)
        try:
            return self.spin_until(lambda: got, timeout, f"a message on {topic}")
        finally:
            self.node.destroy_subscription(sub)

    def wait_for_service(self, client, timeout: float = 15.0) -> float:
        return self.spin_until(client.service_is_ready, timeout,
                               f"service {client.srv_name}")

    def call(self, client, request, timeout: float = 15.0, resend_s: float = 2.0):
        """Call and wait for the response; a query that may be re-asked is re-sent every ``resend_s``.

        Fast DDS drops a response when the server has not yet matched the client's response
        reader ("failed to send response (timeout)"), although ``service_is_ready`` was true on
        the client's side: discovery is asymmetric and slow on a loaded machine. A side-effect-free
        request (the parameter services) is then asked again; any other is
        sent once, so an action is never done twice.
        """
        idempotent = client.srv_type.__name__ in IDEMPOTENT_SERVICES
        futures = [client.call_async(request)]
        end = time.monotonic() + timeout
        while True:
            step = min(resend_s, end - time.monotonic()) if idempotent else end - time.monotonic()
            try:
                self.spin_until(lambda: any(f.done() for f in futures), max(step, 0.0),
                                f"response of {client.srv_name}")
                break
            except TimeoutError:
                if time.monotonic() >= end:
                    raise
                futures.append(client.call_async(request))
        return next(f for f in futures if f.done()).result()

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        self._rclpy.shutdown(context=self.context)


def open_pty_pair():
    """A pseudo-terminal pair in raw mode: (controller fd, device path pyserial can open)."""
    import tty
    controller, device = os.openpty()
    tty.setraw(controller)
    tty.setraw(device)
    path = os.ttyname(device)
    return controller, device, path
