"""A run's node processes under one supervisor and one liveness monitor, the twin's and the robot's.

:class:`SupervisedGraph` starts a graph's nodes, restarts a crashed one with the back-off of the
graph file's liveness budgets (a restarted node must say it is ready within ``restart_grace_s``,
by its typed diagnostics), and each poll acts on the verdicts of the one
:class:`~soft_robot_common.liveness.LivenessMonitor`: a node restarted, or the run stopped with
the contract's reason. Nothing here reads a node's log.
"""
from __future__ import annotations

import time
from pathlib import Path

from soft_robot_common.graph import read_graph_file
from soft_robot_common.liveness import Liveness, LivenessMonitor, liveness_from_graph
from soft_robot_common.supervision import RestartPolicy, Supervisor


def graph_liveness(graph_file, mode: str, nodes, budget_overrides: dict | None = None) -> Liveness:
    """The liveness section of ``graph_file`` for ``mode`` and the run's ``nodes`` (with budget overrides)."""
    meta = read_graph_file(graph_file)["graph"]["ros__parameters"]
    return liveness_from_graph(meta.get("liveness"), mode, nodes, budget_overrides, where=f"graph file {graph_file}")


def parse_budgets(items) -> dict:
    """``["deaf_after_s=6", ...]`` -> ``{"deaf_after_s": 6.0}``; ValueError naming a bad item."""
    out = {}
    for item in items:
        name, eq, value = item.partition("=")
        try:
            out[name.strip()] = float(value) if name.strip() != "max_restarts" else int(value)
        except ValueError:
            raise ValueError(f"--budget {item!r}: expected NAME=SECONDS, e.g. deaf_after_s=6") from None
        if not eq:
            raise ValueError(f"--budget {item!r}: expected NAME=SECONDS, e.g. deaf_after_s=6")
    return out


def run_domain(domain_id: int | None):
    """The run's ROS domain: ``domain_id`` (a user's choice, so ``ros2 topic echo`` can join the run),
    or one no other run on this machine holds."""
    from soft_robot_common.processes import RosDomain, acquire_domain
    if domain_id is None:
        return acquire_domain()
    base = acquire_domain()     # the environment; the caller's domain id replaces the held one
    base.release()
    return RosDomain(domain_id, dict(base.env, ROS_DOMAIN_ID=str(domain_id)))


class SupervisedGraph:
    """The processes of ``graph`` on ``env``, supervised per ``liveness`` (see the module docstring).

    ``restarter(node)`` returns the node's ``start(label)`` for a restart; ``essential`` nodes are
    not restarted (their exit stops the run); ``on_restart(name)`` is told of every restart;
    ``sim_now()`` gives the run's simulated time (None before the first /clock; the wall clock in a
    run on the system clock).
    """

    def __init__(self, graph, liveness: Liveness, env: dict, out: Path, restarter, sim_now, essential=(),
                 log=print, on_restart=None):
        b = liveness.budgets
        self.graph, self.liveness, self.env, self.out = graph, liveness, env, Path(out)
        self.monitor = LivenessMonitor(liveness)
        self.sim_now = sim_now
        self._on_restart = on_restart
        self.supervisor = Supervisor(RestartPolicy(b.max_restarts, b.restart_backoff_s, b.restart_backoff_max_s),
                                     essential=essential, log=log, on_restart=self._restarted)
        self._restarter = restarter
        self.verdicts = []                  # every verdict acted on, for the report

    def start(self, wait_each=None) -> None:
        """Start every node in the graph's order; ``wait_each(node)`` after each (a device to appear)."""
        for node in self.graph:
            proc = node.start(self.env, self.out)
            self.monitor.started(node.name, proc.pid, time.monotonic(), self.sim_now())
            self.supervisor.add(node.name, proc, self._restarter(node),
                                ready=lambda p, n=node.name: self.monitor.ready(n),
                                ready_timeout_s=self.liveness.budgets.restart_grace_s)
            if wait_each is not None:
                wait_each(node)

    def _restarted(self, name: str, proc) -> None:
        self.monitor.started(name, proc.pid, time.monotonic(), self.sim_now())
        if self._on_restart is not None:
            self._on_restart(name)

    def down(self) -> set:
        """Nodes not running, waiting for their restart, or restarted and not ready yet (a node whose
        exit was meant is not coming back: the run goes on without it, and is not waiting for it)."""
        s = self.supervisor
        return {n for n in s.names() if s.down(n) and not s.released(n)} | set(s.recovering())

    def poll(self, held=(), on_verdict=None) -> str | None:
        """Restarts due, then every contract; the reason to stop the run, or None. ``held``: nodes
        silent on purpose now; ``on_verdict(verdict)`` is told of each verdict before it is acted on."""
        reason = self.supervisor.poll()
        if reason:
            return reason
        gone = {n for n in self.supervisor.names() if self.supervisor.released(n)}    # silent for good, on purpose
        restarted = set()
        for v in self.monitor.evaluate(time.monotonic(), self.sim_now(), self.down(), set(held) | gone):
            if v.action == "restart" and (v.node in restarted or v.node not in self.supervisor.names()
                                          or self.supervisor.down(v.node)):
                continue                    # one restart per node (several of its edges can say so at once)
            self.verdicts.append({"action": v.action, "node": v.node, "reason": v.reason, "rule": v.rule,
                                  "sim_time": self.sim_now()})
            if on_verdict is not None:
                on_verdict(v)
            if v.action == "stop":
                return v.reason
            restarted.add(v.node)
            self.supervisor.kill_hung(v.node, v.reason)
        return None

    def edge_topic(self, rule: str) -> str | None:
        """The topic of edge ``rule`` (a verdict's), root-relative."""
        for e in self.liveness.edges:
            if e.name == rule:
                return "/" + e.topic.lstrip("/")
        return None
