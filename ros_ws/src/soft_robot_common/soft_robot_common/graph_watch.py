"""An rclpy node inside a tool's own process, on a run's domain, to watch and drive the graph.

The twins, the real-robot pre-flight, the system tests and the benchmarks all need the same
thing: a private context on the run's ``ROS_DOMAIN_ID`` (never the user's default domain),
one node and one executor spun from the caller's thread, and waits that give up with a
message that says what did not happen (and which node process died meanwhile).
"""

from __future__ import annotations

import os
import sys
import threading
import time
import traceback
from typing import Callable, Iterable

from .processes import MIDDLEWARE_TEARDOWN_S
from .tool_signals import rclpy_call

# GraphWatch.close leaves the teardown behind after MIDDLEWARE_TEARDOWN_S: Fast DDS 2.14 can
# deadlock there (a participant's event thread and a receive thread take its discovery lock and its
# timer lock in opposite orders when remote participants leave).

# teardown threads still blocked in the middleware: the process must then end with os._exit
_ABANDONED: list[threading.Thread] = []


def teardown_abandoned() -> bool:
    """Whether a watch's teardown was left blocked: the caller ends its process with ``os._exit``,
    since the middleware's own exit handlers would block on the same locks."""
    return any(t.is_alive() for t in _ABANDONED)


def exit_status(code: int) -> int:
    """``code``; or, when a watch's teardown was left blocked, the process ends here with it."""
    if teardown_abandoned():
        print(f"exiting with {code} without the middleware's exit handlers (a watch's teardown is blocked)",
              file=sys.stderr, flush=True)
        sys.stdout.flush()
        os._exit(code)
    return code

# Requests with no side effect beyond an idempotent set: safe to re-send. ForwardKinematics is a
# pure query of the finger's model (a re-send costs one more solve); SolveIk is not re-sent: it
# warm-starts from the last solve, so a second one would not answer the same question.
IDEMPOTENT_SERVICES = {"ListParameters", "DescribeParameters", "GetParameters", "GetParameterTypes",
                       "SetParameters", "ForwardKinematics"}


class GraphWatch:
    """One node on domain ``domain_id`` (an int, or anything with a ``domain_id``), spun on demand."""

    def __init__(self, domain_id, name: str = "graph_watch"):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.signals import SignalHandlerOptions
        self._rclpy = rclpy
        self.domain_id = int(getattr(domain_id, "domain_id", domain_id))
        self.context = rclpy.Context()
        # no rclpy signal handler: a tool stops its nodes itself on a signal (tool_signals)
        rclpy.init(context=self.context, domain_id=self.domain_id, signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    # -- spinning -------------------------------------------------------------------------
    def spin_for(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            with rclpy_call():
                self.executor.spin_once(timeout_sec=min(0.05, max(0.0, end - time.monotonic())))

    def spin_until(self, predicate: Callable[[], bool], timeout: float, what: str = "condition",
                   procs: Iterable = ()) -> float:
        """Spin until ``predicate()``; return the seconds it took.

        Raises ``TimeoutError`` naming ``what`` after ``timeout``, or ``RuntimeError`` with the
        log tail of a process of ``procs`` (:class:`~soft_robot_common.processes.NodeProcess`)
        that exited meanwhile.
        """
        start = time.monotonic()
        end = start + timeout
        while time.monotonic() < end:
            if predicate():
                return time.monotonic() - start
            for p in procs:
                if not p.running():
                    raise RuntimeError(f"{p.name} exited early:\n{p.log_text()[-3000:]}")
            with rclpy_call():
                self.executor.spin_once(timeout_sec=0.05)
        if predicate():
            return timeout
        raise TimeoutError(f"{what} not reached within {timeout:g} s")

    # -- the graph ------------------------------------------------------------------------
    def node_names(self) -> set[str]:
        return {ns.rstrip("/") + "/" + n if ns != "/" else "/" + n
                for n, ns in self.node.get_node_names_and_namespaces()}

    def wait_for_node(self, fq_name: str, timeout: float = 15.0) -> float:
        return self.spin_until(lambda: fq_name in self.node_names(), timeout, f"node {fq_name} to appear")

    def wait_node_gone(self, fq_name: str, timeout: float = 15.0) -> float:
        return self.spin_until(lambda: fq_name not in self.node_names(), timeout,
                               f"node {fq_name} to leave the graph")

    def wait_for_topic(self, topic: str, timeout: float = 15.0, publishers: int = 1) -> float:
        return self.spin_until(lambda: self.node.count_publishers(topic) >= publishers,
                               timeout, f"a publisher on {topic}")

    def wait_for_subscriber(self, topic: str, timeout: float = 15.0) -> float:
        return self.spin_until(lambda: self.node.count_subscribers(topic) >= 1,
                               timeout, f"a subscriber on {topic}")

    def subscribed(self, node_name: str, topics) -> bool:
        """Whether node ``node_name`` subscribes to every topic of ``topics`` (graph discovery)."""
        return all(any(info.node_name == node_name for info in self.node.get_subscriptions_info_by_topic(t))
                   for t in topics)

    def wait_matched(self, publisher, subscribers: int = 1, timeout: float = 30.0) -> float:
        """Wait until ``publisher`` (this node's) has matched ``subscribers`` readers in DDS.

        The graph (:meth:`wait_for_subscriber`) shows a subscription before this node's writer
        has matched it; a reliable, volatile message published in between is lost. The match
        count is the writer's own view: a message published after this returns is delivered.
        """
        return self.spin_until(lambda: publisher.get_subscription_count() >= subscribers, timeout,
                               f"{subscribers} matched subscriber(s) on {publisher.topic_name}")

    def wait_heard(self, msg_type, topic: str, timeout: float = 30.0, qos=10, accept=None) -> float:
        """Wait for one message on ``topic`` through a new subscription (then destroyed).

        The publishing process has then discovered this subscription, and with it every
        subscription this node created before (Fast DDS announces a participant's endpoints in
        creation order on one reliable channel): its outputs on those topics now reach us.
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

    def wait_ready(self, node_name: str, pid: int | None = None, keys=("ready",), timeout: float = 60.0,
                   procs: Iterable = ()) -> float:
        """Wait until node ``node_name`` (process ``pid``, if given) says in its ``/diagnostics`` that it
        works: every key of ``keys`` present and not ``false`` (NodeDiagnostics' typed values)."""
        from diagnostic_msgs.msg import DiagnosticArray
        seen = []

        def on_diag(msg):
            for st in msg.status:
                if st.name.split(":", 1)[0] != node_name:
                    continue
                values = {kv.key: kv.value for kv in st.values}
                if (pid is None or values.get("pid") == str(pid)) and all(
                        values.get(k, "false") not in ("false", "") for k in keys):
                    seen.append(True)
        sub = self.node.create_subscription(DiagnosticArray, "/diagnostics", on_diag, 50)
        try:
            return self.spin_until(lambda: seen, timeout, f"{node_name} ready (its diagnostics)", procs)
        finally:
            self.node.destroy_subscription(sub)

    # -- services -------------------------------------------------------------------------
    def wait_for_service(self, client, timeout: float = 15.0) -> float:
        return self.spin_until(client.service_is_ready, timeout, f"service {client.srv_name}")

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
        """Destroy the node and its context (again: nothing). A teardown that does not return within
        ``MIDDLEWARE_TEARDOWN_S`` is left behind in its thread, with a message saying where it is."""
        if getattr(self, "_closing", False) or not self.context.ok():
            return
        self._closing = True

        def teardown():
            self.executor.shutdown()
            self.node.destroy_node()
            self._rclpy.shutdown(context=self.context)

        thread = threading.Thread(target=teardown, name="graph_watch teardown", daemon=True)
        thread.start()
        thread.join(MIDDLEWARE_TEARDOWN_S)
        if thread.is_alive():
            _ABANDONED.append(thread)
            frame = sys._current_frames().get(thread.ident)
            where = "".join(traceback.format_stack(frame)) if frame is not None else "(no frame)\n"
            print(f"graph watch on domain {self.domain_id}: the middleware's teardown (destroy_node, "
                  f"rclpy.shutdown) is still blocked after {MIDDLEWARE_TEARDOWN_S:g} s; leaving it behind. "
                  f"Where it is:\n{where}", file=sys.stderr, flush=True)
