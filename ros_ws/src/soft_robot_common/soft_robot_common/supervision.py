"""Supervision of a run's node processes: restart a crashed node with back-off, and say so.

A node that exits while the run goes on (a crash, a SIGKILL, the OOM killer) is started
again with the same command line after a back-off that doubles per restart of that node
(``backoff_s``, ``2 backoff_s``, ... up to ``backoff_max_s``), at most ``max_restarts``
times. Nodes named in ``essential`` are not restarted (the simulated world: a new one would
start from the initial pose); their exit, or a node out of restarts, ends the run with the
reason in :attr:`Supervisor.stop_reason`. A node may also have a readiness check (a predicate
of its process, true once the node says it works: its typed diagnostics, a service), which each
restart must pass within ``ready_timeout_s``: a restarted process that is running but never gets
ready (a middleware hang, docs/faults.md) is SIGKILLed and handled as a crash, as is one the
caller finds hung by its own check (:meth:`Supervisor.kill_hung`). The first start is the
caller's to wait for.
Every exit and restart is an event with its time, printed and kept for the run's report.
Pure Python (no rclpy).
"""

from __future__ import annotations

import signal
import time
from dataclasses import dataclass, field
from typing import Callable, Optional

from .processes import NodeProcess


#: A stop slower than this [s] is mentioned (a node whose middleware teardown blocked, node_main).
SLOW_STOP_S = 3.0


@dataclass(frozen=True)
class RestartPolicy:
    """How often and how soon a crashed node is started again."""

    max_restarts: int = 3
    backoff_s: float = 1.0
    backoff_max_s: float = 8.0

    def __post_init__(self):
        if self.max_restarts < 0 or not (0 <= self.backoff_s <= self.backoff_max_s):
            raise ValueError(f"restart policy: need max_restarts >= 0 and 0 <= backoff_s <= backoff_max_s, got "
                             f"{self.max_restarts}, {self.backoff_s}, {self.backoff_max_s}")

    def delay(self, restarts_so_far: int) -> float:
        return min(self.backoff_max_s, self.backoff_s * 2.0 ** restarts_so_far)


@dataclass
class SupervisionEvent:
    """One exit or restart: wall time (time.monotonic), node, what, and the exit code."""

    time: float
    node: str
    what: str            # "exited" (a restart follows), "restarted", "not restarted", "released", "hung"
    code: Optional[int] = None
    detail: str = ""

    def as_dict(self) -> dict:
        return {"time": self.time, "node": self.node, "what": self.what, "code": self.code, "detail": self.detail}


def describe_exit(code: Optional[int]) -> str:
    """'exit 1', 'SIGKILL', ... for a Popen return code."""
    if code is None:
        return "running"
    if code < 0:
        try:
            return signal.Signals(-code).name
        except ValueError:
            return f"signal {-code}"
    return f"exit {code}"


@dataclass
class _Slot:
    name: str
    start: Callable[[str], NodeProcess]      # label -> started process
    process: NodeProcess
    restarts: int = 0
    due: Optional[float] = None               # monotonic time of the pending restart
    given_up: bool = False                    # essential, or out of restarts
    released: bool = False                    # its exit was meant (release)
    ended_run: bool = False                   # its exit (crash or hang, not restarted) is the stop reason
    history: list = field(default_factory=list)   # every process this slot ran
    ready: Optional[Callable[[NodeProcess], bool]] = None     # true once the process's node works
    ready_timeout_s: float = 0.0
    ready_seen: bool = False


class Supervisor:
    """Watches started processes (:meth:`add`) and restarts crashed ones (:meth:`poll`)."""

    def __init__(self, policy: RestartPolicy = RestartPolicy(), essential=(), log: Callable[[str], None] = print,
                 on_restart: Optional[Callable[[str, NodeProcess], None]] = None):
        self.policy = policy
        self.essential = set(essential)
        self.log = log
        self.on_restart = on_restart
        self.events: list[SupervisionEvent] = []
        self.stop_reason: Optional[str] = None
        self._slots: dict[str, _Slot] = {}

    def add(self, name: str, process: NodeProcess, start: Callable[[str], NodeProcess],
            ready: Optional[Callable[[NodeProcess], bool]] = None, ready_timeout_s: float = 30.0) -> None:
        """Supervise ``process`` of node ``name``; ``start(label)`` starts it again (log ``<label>.log``).

        ``ready(process)``: true once a restarted process works; one that is not ready within
        ``ready_timeout_s`` is taken for hung: SIGKILLed, then restarted (or given up) like a crash."""
        if ready is not None and not ready_timeout_s > 0:
            raise ValueError(f"ready_timeout_s {ready_timeout_s!r} must be > 0")
        self._slots[name] = _Slot(name, start, process, history=[process], ready=ready,
                                  ready_timeout_s=ready_timeout_s)

    def process(self, name: str) -> NodeProcess:
        return self._slots[name].process

    def processes(self) -> list[NodeProcess]:
        """Every process started (restarts included), in start order of their nodes."""
        return [p for s in self._slots.values() for p in s.history]

    def unclean_stops(self) -> list[str]:
        """Nodes whose last process did not end by SIGINT with code 0 at the run's stop (released nodes,
        nodes whose exit ended the run, named in :attr:`stop_reason`, and nodes waiting for their
        restart, whose process ended before the stop as an event says, excepted)."""
        return [s.name for s in self._slots.values()
                if not (s.released or s.ended_run or s.due is not None) and not s.process.stopped_cleanly]

    def names(self) -> list[str]:
        return list(self._slots)

    def release(self, name: str, why: str) -> None:
        """Stop supervising ``name`` (an exit that is meant: no restart, no stop of the run)."""
        slot = self._slots[name]
        slot.given_up = slot.released = True
        self._event(name, "released", None, why)

    def recovering(self) -> list[str]:
        """Nodes on their way back: waiting for their restart, or restarted and not yet ready."""
        return [s.name for s in self._slots.values() if not s.given_up and (
            s.due is not None or (s.restarts and s.ready is not None and not s.ready_seen and s.process.running()))]

    def down(self, name: str) -> bool:
        """Whether node ``name`` is not running now (crashed, waiting for its restart)."""
        return not self._slots[name].process.running()

    def released(self, name: str) -> bool:
        """Whether node ``name``'s exit was meant (:meth:`release`): it is not coming back."""
        return self._slots[name].released

    def _event(self, node: str, what: str, code=None, detail: str = "") -> None:
        ev = SupervisionEvent(time.monotonic(), node, what, code, detail)
        self.events.append(ev)
        self.log(f"supervisor: {node} {what}" + (f" ({describe_exit(code)})" if code is not None else "")
                 + (f": {detail}" if detail else ""))

    def poll(self, now: Optional[float] = None) -> Optional[str]:
        """Handle exits and due restarts; the reason to stop the run, or None to go on."""
        now = time.monotonic() if now is None else now
        for slot in self._slots.values():
            if slot.given_up:
                continue
            if (slot.due is None and slot.restarts and slot.ready is not None and not slot.ready_seen
                    and slot.process.running()):
                self._check_ready(slot, now)
            if slot.due is None and not slot.process.running():
                code = slot.process.proc.returncode
                slot.process.stop()      # reap what is left of its process group, close its log
                if slot.name in self.essential or slot.restarts >= self.policy.max_restarts:
                    slot.given_up = slot.ended_run = True
                    detail = ("essential, not restarted" if slot.name in self.essential
                              else f"{slot.restarts} restart(s) used")
                    self._event(slot.name, "not restarted", code, detail)
                    self.stop_reason = self.stop_reason or (
                        f"{slot.name} exited ({describe_exit(code)}; {detail}); log {slot.process.log_path}")
                else:
                    slot.due = now + self.policy.delay(slot.restarts)
                    self._event(slot.name, "exited", code, f"restart {slot.restarts + 1} in {slot.due - now:.1f} s")
            elif slot.due is not None and now >= slot.due:
                slot.restarts += 1
                slot.due = None
                slot.process = slot.start(f"{slot.name}.{slot.restarts}")
                slot.history.append(slot.process)
                slot.ready_seen = False
                self._event(slot.name, "restarted", None, f"restart {slot.restarts}, log {slot.process.log_path}")
                if self.on_restart is not None:
                    self.on_restart(slot.name, slot.process)
        return self.stop_reason

    def _check_ready(self, slot: _Slot, now: float) -> None:
        """Kill a process that has not got ready in time (poll() then restarts it)."""
        if slot.ready(slot.process):
            slot.ready_seen = True
        elif now - slot.process.started_at > slot.ready_timeout_s:
            self.kill_hung(slot.name, f"not ready within {slot.ready_timeout_s:g} s of its start")

    def kill_hung(self, name: str, why: str) -> None:
        """SIGKILL node ``name``, running but not working (``why``); poll() then restarts it like a crash."""
        slot = self._slots[name]
        self._event(name, "hung", None, f"{why}; SIGKILL")
        slot.process.send(signal.SIGKILL)
        slot.process.wait(10)

    def stop_all(self, warn: Callable[[str], None] = print) -> None:
        """Stop every running process in reverse start order; warn for any that did not exit 0."""
        for slot in reversed(list(self._slots.values())):
            slot.given_up = True
            p = slot.process
            if p.running():
                code = p.stop()
                if code not in (0, None):
                    warn(f"  warning: {p.name} exited with {code}; log {p.log_path}")
                elif p.stop_seconds > SLOW_STOP_S:
                    warn(f"  note: {p.name} took {p.stop_seconds:.1f} s to stop; log {p.log_path}")

    def summary(self) -> dict:
        return {"restarts": {s.name: s.restarts for s in self._slots.values()},
                "events": [e.as_dict() for e in self.events], "stop_reason": self.stop_reason,
                "stops": {s.name: s.process.stop_report() for s in self._slots.values()}}

