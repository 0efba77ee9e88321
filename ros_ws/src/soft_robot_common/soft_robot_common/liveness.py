"""Liveness declared once: the graph file's contracts, their budgets, and the one monitor.

A graph file (:mod:`.graph`) declares, in its ``graph.liveness`` section,

- ``budgets``: every timeout of a run's supervision (:class:`Budgets`), whose order is checked
  here, not kept by comments;
- ``edges``: for each edge of the loop, the topic, its producer and consumer, what it carries,
  its expected rate, how long it may be silent (a budget's name) and what happens then
  (:data:`ACTIONS`): a producer that falls silent, and a consumer that hears nothing while its
  producer publishes (``producer_count`` / ``consumer_count``: the two nodes' typed diagnostics
  keys; without ``producer_count`` the monitor counts the arrivals it sees itself);
- ``states``: typed states that end the run or restart a node when they hold long enough (a
  latched emergency, a planner that does not follow, a tag lost);
- ``ready``: per node, the diagnostics keys that say it works (default ``ready``).

:class:`LivenessMonitor` evaluates them from message arrivals and diagnostics values, never
from log text or free-form messages, and returns :class:`Verdict` items; the caller restarts
or stops. It is pure Python with the times passed in (a fake clock in the tests).
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

#: What an edge or state rule does when it is broken.
ACTIONS = ("wait", "restart_producer", "restart_consumer", "restart", "stop")
CLOCKS = ("wall", "sim")


class LivenessError(ValueError):
    """A liveness section that cannot be used; the message names the entry and the problem."""


@dataclass(frozen=True)
class Budgets:
    """Every timeout of a run's supervision [s]; 0 turns a check off where the field says so.

    The order between them matters and is checked (:meth:`problems`): see each rule's reason.
    """

    restart_backoff_s: float = 1.0          # first restart of a crashed node after this; doubles per restart
    restart_backoff_max_s: float = 8.0      # ... up to this
    max_restarts: int = 3                   # per node; then the run stops with the reason
    restart_grace_s: float = 15.0           # a restarted node not ready by then is hung: killed, restarted
    diagnostics_period_s: float = 1.0       # every node's /diagnostics (NodeDiagnostics)
    deaf_after_s: float = 8.0               # a live consumer that hears nothing this long (wall; 0 = off)
    world_stall_s: float = 10.0             # /clock not advancing this long stops the run (wall; 0 = off)
    stuck_after_s: float = 20.0             # the planner not following this long stops the run (simulated)
    tag_lost_after_s: float = 3.0           # the real robot: the tag not seen this long stops the run (wall)

    def __post_init__(self):
        problems = self.problems()
        if problems:
            raise LivenessError("liveness budgets: " + "; ".join(problems))

    def problems(self) -> list[str]:
        """Why these budgets cannot be used together (each broken rule with its reason), or []."""
        out = []
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                out.append(f"{f.name} = {v!r} must be a finite number >= 0")
        if out:
            return out
        positive = ("restart_grace_s", "diagnostics_period_s", "stuck_after_s", "tag_lost_after_s")
        out += [f"{n} = {getattr(self, n)} must be > 0" for n in positive if not getattr(self, n) > 0]
        for lhs, rhs, why in self.ORDER:
            a, b = getattr(self, lhs), getattr(self, rhs)
            if a and b and not a < b:
                out.append(f"{lhs} ({a:g} s) must be below {rhs} ({b:g} s): {why}")
        if not self.restart_backoff_s <= self.restart_backoff_max_s:
            out.append(f"restart_backoff_s ({self.restart_backoff_s:g} s) must not exceed restart_backoff_max_s "
                       f"({self.restart_backoff_max_s:g} s)")
        if self.deaf_after_s and not 2 * self.diagnostics_period_s < self.deaf_after_s:
            out.append(f"deaf_after_s ({self.deaf_after_s:g} s) must exceed two diagnostics periods "
                       f"({2 * self.diagnostics_period_s:g} s): a consumer's count comes once a period")
        return out

    #: (shorter, longer, why) pairs; a 0 (off) on either side skips the rule.
    ORDER = (
        ("world_stall_s", "restart_grace_s", "a stalled world starves every restarted node of /clock, which must "
         "not spend its restarts before the run stops for the stall"),
        ("deaf_after_s", "stuck_after_s", "a deaf node is found and restarted before the run is declared stuck"),
        ("restart_backoff_max_s", "stuck_after_s", "a crashed node's restart comes before the run is declared "
         "stuck"),
    )


@dataclass(frozen=True)
class Edge:
    """One edge of the loop and its contract (see the module docstring)."""

    name: str
    topic: str
    producers: tuple
    consumer: str
    carries: str
    rate_hz: float
    silence: str                  # a Budgets field
    then: str = "wait"            # the producer silent
    deaf: str = "wait"            # the consumer hears nothing while the producer publishes
    clock: str = "wall"
    producer_count: str = ""      # producer's diagnostics key counting what it published ("" = arrivals seen)
    consumer_count: str = ""      # consumer's diagnostics key counting what it received ("" = not checked)
    min_messages: int = 3         # published meanwhile, for a silent consumer to count as deaf
    modes: tuple = ("sim", "real")


@dataclass(frozen=True)
class StateRule:
    """A typed state (``node``'s ``key`` in ``values``, or not in them with ``negate``) that, held for
    the budget ``after`` (or at once with ``after`` empty), does ``then`` with the reason ``says``."""

    name: str
    node: str
    key: str
    values: tuple
    says: str
    then: str = "stop"
    after: str = ""
    negate: bool = False
    clock: str = "wall"
    detail: str = ""              # a diagnostics key of the node whose value the reason quotes
    during_recovery: bool = False  # also while a node recovers (an emergency); else a recovering run waits
    modes: tuple = ("sim", "real")


@dataclass(frozen=True)
class Liveness:
    """The liveness section of a graph in one mode (only the nodes it runs)."""

    budgets: Budgets = Budgets()
    edges: tuple = ()
    states: tuple = ()
    ready: dict = field(default_factory=dict)      # node -> diagnostics keys that say it works

    def ready_keys(self, node: str) -> tuple:
        return tuple(self.ready.get(node, ("ready",)))


@dataclass(frozen=True)
class Verdict:
    """What the monitor asks the caller to do: restart ``node``, or stop the run; ``reason`` says why."""

    action: str                   # "restart" or "stop"
    node: str | None
    reason: str
    rule: str
    since_sim: float | None = None  # an edge's consumer: simulated time it last heard (None: not known)


def _tuple(value) -> tuple:
    return tuple(value) if isinstance(value, (list, tuple)) else (value,) if value not in (None, "") else ()


def liveness_from_graph(section: dict | None, mode: str, nodes, budget_overrides: dict | None = None,
                        where: str = "graph file") -> Liveness:
    """The :class:`Liveness` of a graph file's ``liveness`` section for ``mode`` and the run's ``nodes``.

    Entries whose nodes the run does not start are left out (``--no-vision`` has no camera edge).
    ``budget_overrides`` replace budgets by name (a run's options). Raises :class:`LivenessError`
    naming the entry for an unknown field, action, clock or budget, and for budgets out of order.
    """
    section = section or {}
    nodes = set(nodes)
    try:
        budgets = Budgets(**{**(section.get("budgets") or {}), **(budget_overrides or {})})
    except TypeError as exc:
        raise LivenessError(f"{where}: liveness.budgets: {exc}") from None
    names = {f.name for f in dataclasses.fields(Budgets)}
    edges, states = [], []
    for kind, cls, out in (("edges", Edge, edges), ("states", StateRule, states)):
        known = {f.name for f in dataclasses.fields(cls)} - {"name"}
        for name, spec in (section.get(kind) or {}).items():
            if not isinstance(spec, dict) or set(spec) - known:
                raise LivenessError(f"{where}: liveness.{kind}.{name}: unknown field(s) "
                                    f"{sorted(set(spec) - known) if isinstance(spec, dict) else spec!r}; "
                                    f"expected of {sorted(known)}")
            spec = dict(spec)
            for key in ("producers", "values", "modes"):
                if key in spec:
                    spec[key] = _tuple(spec[key])
            try:
                item = cls(name=name, **spec)
            except TypeError as exc:
                raise LivenessError(f"{where}: liveness.{kind}.{name}: {exc}") from None
            for attr in ("then", "deaf"):
                if getattr(item, attr, "wait") not in ACTIONS:
                    raise LivenessError(f"{where}: liveness.{kind}.{name}.{attr} {getattr(item, attr)!r}: expected "
                                        f"one of {', '.join(ACTIONS)}")
            if item.clock not in CLOCKS:
                raise LivenessError(f"{where}: liveness.{kind}.{name}.clock {item.clock!r}: expected wall or sim")
            budget = item.silence if kind == "edges" else item.after
            if budget and budget not in names:
                raise LivenessError(f"{where}: liveness.{kind}.{name}: {budget!r} is not a budget "
                                    f"({', '.join(sorted(names))})")
            if mode not in item.modes:
                continue
            if kind == "edges":
                present = tuple(p for p in item.producers if p in nodes)
                if not present or (item.consumer not in nodes and item.consumer != "run"):
                    continue
                item = dataclasses.replace(item, producers=present)
            elif item.node not in nodes:
                continue
            out.append(item)
    ready = {n: _tuple(keys) for n, keys in (section.get("ready") or {}).items()}
    return Liveness(budgets, tuple(edges), tuple(states), ready)


class _EdgeWatch:
    """Silence and deafness of one edge (times on the edge's clock)."""

    def __init__(self):
        self.produced_at = None      # last producer activity
        self.heard_at = None         # last consumer activity (or the start of the wait)
        self.heard_sim = None        # simulated time the consumer last heard
        self.published = 0           # producer messages since heard_at
        self.counts = {}             # (node, key) -> last count seen

    def restart(self, now) -> None:
        self.produced_at = self.heard_at = now
        self.published = 0


class LivenessMonitor:
    """Evaluates a :class:`Liveness` (see the module docstring).

    Feed it :meth:`started` (a node's process, and its pid, started or restarted),
    :meth:`message` (an arrival the caller saw on an edge's topic), :meth:`diagnostics` (a node's
    typed diagnostics values) and :meth:`value` (a typed state from a message, e.g. the planner's
    status); ask :meth:`ready` and :meth:`evaluate`. ``now`` is wall time, ``sim`` simulated time
    (None before the first /clock).
    """

    def __init__(self, liveness: Liveness):
        self.liveness = liveness
        self._pid = {}               # node -> pid of its current process (None: not known)
        self._ready = {}             # node -> its current process said it works
        self._values = {}            # (node, key) -> (value, since wall, since sim)
        self._edges = {e.name: _EdgeWatch() for e in liveness.edges}
        self._states = {}            # rule name -> (wall, sim) since it holds

    # -- inputs -------------------------------------------------------------------------------
    def started(self, node: str, pid: int | None, now: float, sim: float | None = None) -> None:
        """Node ``node`` runs a new process ``pid``: not ready until it says so; its edges wait anew."""
        self._pid[node] = pid
        self._ready[node] = False
        for key in [k for k in self._values if k[0] == node]:
            del self._values[key]
        for e in self.liveness.edges:
            if node in e.producers or node == e.consumer:
                self._edges[e.name].restart(self._now(e.clock, now, sim))

    def restart(self, now: float, sim: float | None = None) -> None:
        """Every edge's wait starts again now (the run starts: what came before it does not count)."""
        for e in self.liveness.edges:
            self._edges[e.name].restart(self._now(e.clock, now, sim))
        self._states.clear()

    def message(self, topic: str, now: float, sim: float | None = None) -> None:
        """An arrival on ``topic`` (root-relative names match an edge's relative topic)."""
        for e in self.liveness.edges:
            if not e.producer_count and _same_topic(e.topic, topic):
                self._produced(e, self._now(e.clock, now, sim), 1)

    def diagnostics(self, node: str, values: dict, now: float, sim: float | None = None) -> None:
        """A diagnostics status of ``node`` (its values as text, with ``pid``)."""
        pid = values.get("pid")
        known = self._pid.get(node)
        if pid is not None and known is not None and str(known) != str(pid):
            return                          # a predecessor's last word, or another process of that name
        if all(values.get(k, "false") not in ("false", "") for k in self.liveness.ready_keys(node)):
            self._ready[node] = True
        for key, v in values.items():
            self.value(node, key, v, now, sim)
        for e in self.liveness.edges:
            t = self._now(e.clock, now, sim)
            w = self._edges[e.name]
            if node in e.producers and e.producer_count in values:
                self._produced(e, t, self._rise(w, node, e.producer_count, values))
            if node == e.consumer and e.consumer_count in values and self._rise(w, node, e.consumer_count, values):
                w.heard_at, w.heard_sim, w.published = t, sim, 0

    def value(self, node: str, key: str, value, now: float, sim: float | None = None) -> None:
        """A typed state: ``node``'s ``key`` is ``value`` (text) from now on."""
        old = self._values.get((node, key))
        if old is None or old[0] != str(value):
            self._values[(node, key)] = (str(value), now, sim)

    # -- queries ------------------------------------------------------------------------------
    def ready(self, node: str) -> bool:
        """Whether ``node``'s current process has said it works (its ready keys)."""
        return self._ready.get(node, False)

    def latest(self, node: str, key: str) -> str | None:
        v = self._values.get((node, key))
        return None if v is None else v[0]

    def evaluate(self, now: float, sim: float | None, down=(), held=()) -> list[Verdict]:
        """The verdicts of every contract now. ``down``: nodes not running or recovering (crashed,
        waiting for their restart, restarted and not ready yet); ``held``: nodes silent on purpose
        (stopped by a fault, the clock paused). Both excuse the edges they are on, whose wait starts
        again after; ``down`` also excuses every state rule (a run recovering is not stuck)."""
        out = []
        down, held = set(down), set(held)
        b = self.liveness.budgets
        for e in self.liveness.edges:
            t = self._now(e.clock, now, sim)
            w = self._edges[e.name]
            bound = getattr(b, e.silence)
            if t is None or not bound:
                continue
            if (set(e.producers) | {e.consumer}) & (down | held) or w.produced_at is None:
                w.restart(t)
                continue
            if e.consumer_count and (e.consumer, e.consumer_count) not in self._values:
                w.heard_at, w.published = t, 0      # the consumer has not subscribed to it yet
            producer = "/".join(e.producers)
            silent = t - w.produced_at
            if silent >= bound and e.then != "wait":
                out.append(self._verdict(e.then, e, producer, f"{producer} published nothing on {e.topic} "
                                                              f"({e.carries}) for {silent:.1f} s"))
                w.restart(t)
                continue
            deaf = t - w.heard_at
            if e.consumer_count and e.deaf != "wait" and deaf >= bound and w.published >= e.min_messages:
                v = self._verdict(e.deaf, e, producer, f"{e.consumer} received nothing on {e.topic} for {deaf:.1f} s "
                                                      f"while {producer} published {w.published}")
                out.append(dataclasses.replace(v, since_sim=w.heard_sim))
                w.restart(t)
        for r in self.liveness.states:
            t = self._now(r.clock, now, sim)
            v = self._values.get((r.node, r.key))
            holds = v is not None and ((v[0] in r.values) != r.negate)
            if t is None or not holds or (down and not r.during_recovery) or r.node in held:
                self._states.pop(r.name, None)
                continue
            since = self._states.setdefault(r.name, t)
            after = getattr(b, r.after) if r.after else 0.0
            if t - since >= after:
                detail = self.latest(r.node, r.detail) if r.detail else None
                reason = r.says + (f" ({r.key} {v[0]}" + (f": {detail}" if detail else "") + ")")
                if after:
                    reason += f" for {t - since:.1f} s"
                out.append(Verdict("stop" if r.then == "stop" else "restart", r.node, reason, r.name))
                self._states.pop(r.name, None)
        return out

    # -- helpers ------------------------------------------------------------------------------
    @staticmethod
    def _now(clock: str, now: float, sim: float | None):
        return now if clock == "wall" else sim

    def _produced(self, e: Edge, t, n: int) -> None:
        if t is None or n <= 0:
            return
        w = self._edges[e.name]
        w.produced_at = t
        w.published += n
        if w.heard_at is None:
            w.heard_at = t

    @staticmethod
    def _rise(w: _EdgeWatch, node: str, key: str, values: dict) -> int:
        """How much ``node``'s count ``key`` rose since last seen (a smaller one: a new process, its count)."""
        try:
            count = int(float(values[key]))
        except (TypeError, ValueError):
            return 0
        last = w.counts.get((node, key))
        w.counts[(node, key)] = count
        if last is None:
            return 0
        return count - last if count >= last else count

    @staticmethod
    def _verdict(action: str, e: Edge, producer: str, text: str) -> Verdict:
        if action == "stop":
            return Verdict("stop", None, text, e.name)
        node = e.consumer if action == "restart_consumer" else e.producers[0]
        return Verdict("restart", node, text, e.name)


def _same_topic(edge_topic: str, topic: str) -> bool:
    return topic == edge_topic or topic == "/" + edge_topic.lstrip("/")
