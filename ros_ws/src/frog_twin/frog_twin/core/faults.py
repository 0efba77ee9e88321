"""Faults injected into the running twin: the spec, and what a run did under them.

A fault spec is a ``;``-separated list of ``KIND[:NODE]@AT[+DURATION][,key=value...]``::

    camera_freeze@10+5            the camera repeats its last frame from 10 s for 5 s
    camera_stop@10+5              no frames at all
    occlude@10+3                  the tag is covered (the robot under an occluder)
    frame_drop@10+8,rate=0.5      half the frames lost
    ble_loss@10+5,rate=0.8        80 % of the lines to the robot lost over BLE
    unplug@10+2                   the relay's USB device gone, then back
    emergency@10                  the robot reports EMERGENCY (latched: the run stops)
    kill:tracker_node@10          SIGKILL; the supervisor restarts it (restart=no: it stays dead)
    clock_stall@10+3              the simulation (and /clock) pauses for 3 wall seconds
    sigstop:planner_node@10+4     SIGSTOP, SIGCONT 4 wall seconds later (CPU starvation)

``AT`` is in simulated seconds after the planner's start; durations are simulated seconds,
except for ``clock_stall`` and ``sigstop`` (wall seconds: a paused clock does not run).
Pure Python: parsing, the campaign's plan, and the metrics of one run: what the twin's watch
node saw (which does not depend on the recorder, one of the nodes under test) and the audit of
the state behind every pulse (:mod:`frog_twin.core.state_audit`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

#: fault kind -> (needs a duration, node class it needs in the graph, its default options)
KINDS = {
    "camera_freeze": (True, "vision", {}),
    "camera_stop": (True, "vision", {}),
    "occlude": (True, "vision", {}),
    "frame_drop": (True, "vision", {"rate": 0.5}),
    "ble_loss": (True, "serial", {"rate": 0.8}),
    "unplug": (True, "serial", {}),
    "emergency": (False, "serial", {}),
    "kill": (False, None, {"restart": "yes"}),
    "clock_stall": (True, None, {}),
    "sigstop": (True, None, {}),
}
#: nodes ``kill`` and ``sigstop`` may target (the world, sim_node, and the robot are not faults of the stack;
#: the world may be stopped for a while: ``sigstop:sim_node``, a starved simulator)
TARGETS = ("tracker_node", "planner_node", "bridge_node", "recorder", "camera_sim", "image_preview")
WALL_DURATION = ("clock_stall", "sigstop")


@dataclass(frozen=True)
class Fault:
    kind: str
    at: float                    # simulated s after the planner's start
    duration: float = 0.0        # simulated s (wall s for clock_stall and sigstop)
    target: str = ""
    rate: float = math.nan
    restart: bool = True

    @property
    def end(self) -> float:
        """Simulated time the fault ends (its start for instant faults and wall-timed ones)."""
        return self.at + (0.0 if self.kind in WALL_DURATION else self.duration)

    def label(self) -> str:
        s = self.kind + (f":{self.target}" if self.target else "") + f"@{self.at:g}"
        if KINDS[self.kind][0]:
            s += f"+{self.duration:g}"
        if self.kind in ("frame_drop", "ble_loss"):
            s += f",rate={self.rate:g}"
        if self.kind == "kill" and not self.restart:
            s += ",restart=no"
        return s


class FaultSpecError(ValueError):
    """A fault spec that cannot be used; the message names the item and the problem."""


def parse_faults(spec: str) -> list[Fault]:
    """The faults of ``spec`` (see the module docstring), in time order."""
    faults = []
    for item in (s.strip() for s in spec.split(";")):
        if item:
            faults.append(_parse_one(item))
    if not faults:
        raise FaultSpecError(f"fault spec {spec!r} names no fault; e.g. 'camera_freeze@10+5;kill:tracker_node@20'")
    return sorted(faults, key=lambda f: f.at)


def _parse_one(item: str) -> Fault:
    head, *opts = item.split(",")
    if "@" not in head:
        raise FaultSpecError(f"fault {item!r}: no '@time' (e.g. {head}@10+5)")
    what, when = head.split("@", 1)
    kind, _, target = what.partition(":")
    if kind not in KINDS:
        raise FaultSpecError(f"fault {item!r}: unknown kind {kind!r}; expected one of {', '.join(KINDS)}")
    needs_duration, _, defaults = KINDS[kind]
    at_text, plus, dur_text = when.partition("+")
    try:
        at = float(at_text)
        duration = float(dur_text) if plus else 0.0
    except ValueError:
        raise FaultSpecError(f"fault {item!r}: time {when!r} is not AT[+DURATION] in seconds") from None
    if not (math.isfinite(at) and at >= 0 and math.isfinite(duration) and duration >= 0):
        raise FaultSpecError(f"fault {item!r}: time and duration must be finite and >= 0")
    if needs_duration and not duration > 0:
        raise FaultSpecError(f"fault {item!r}: {kind} needs a duration > 0 (e.g. {kind}@{at_text}+5)")
    if not needs_duration and plus:
        raise FaultSpecError(f"fault {item!r}: {kind} takes no duration")
    if kind in ("kill", "sigstop"):
        if target not in TARGETS + (("sim_node",) if kind == "sigstop" else ()):
            raise FaultSpecError(f"fault {item!r}: {kind} needs a node, one of {', '.join(TARGETS)} "
                                 f"(e.g. {kind}:tracker_node@{at_text})")
    elif target:
        raise FaultSpecError(f"fault {item!r}: {kind} takes no node")
    values = dict(defaults)
    for opt in opts:
        key, eq, value = opt.partition("=")
        key = key.strip()
        if not eq or key not in defaults:
            allowed = ", ".join(defaults) or "none"
            raise FaultSpecError(f"fault {item!r}: option {opt!r} is not key=value with a key of {kind} ({allowed})")
        values[key] = value.strip()
    rate = math.nan
    if "rate" in values:
        try:
            rate = float(values["rate"])
        except ValueError:
            rate = math.nan
        if not 0.0 < rate <= 0.99:
            raise FaultSpecError(f"fault {item!r}: rate must be in (0, 0.99], got {values['rate']!r}")
    restart = True
    if "restart" in values:
        if values["restart"] not in ("yes", "no"):
            raise FaultSpecError(f"fault {item!r}: restart must be yes or no, got {values['restart']!r}")
        restart = values["restart"] == "yes"
    return Fault(kind, at, duration, target, rate, restart)


def check_against_graph(faults, nodes) -> None:
    """Raise :class:`FaultSpecError` for faults whose nodes the run does not have (--no-vision, --direct)."""
    nodes = set(nodes)
    need = {"vision": "camera_sim", "serial": "robot_emulator"}
    for f in faults:
        cls = KINDS[f.kind][1]
        if cls is not None and need[cls] not in nodes:
            raise FaultSpecError(f"fault {f.label()}: needs {need[cls]}, which this run does not start "
                                 f"({'--no-vision' if cls == 'vision' else '--direct'})")
        if f.target and f.target not in nodes:
            raise FaultSpecError(f"fault {f.label()}: node {f.target} is not in this run")


# -- the campaign's plan -------------------------------------------------------------------------
#: one representative of each fault the campaign runs; durations well beyond the state-age bound
#: (0.5 s) where staleness is what the fault tests, and the stops of the vision-to-decision chain
#: (5 s) and of the world (3 s) that signals from outside also send (frog_twin.outside_faults)
CAMPAIGN_FAULTS = (
    "camera_freeze@0+5", "camera_stop@0+5", "occlude@0+4", "frame_drop@0+8,rate=0.5", "ble_loss@0+5,rate=0.8",
    "unplug@0+2", "emergency@0", "kill:tracker_node@0", "kill:planner_node@0", "kill:bridge_node@0",
    "kill:recorder@0", "kill:camera_sim@0", "kill:tracker_node@0,restart=no", "clock_stall@0+3",
    "sigstop:planner_node@0+5", "sigstop:tracker_node@0+5", "sigstop:camera_sim@0+5", "sigstop:sim_node@0+3",
)
#: the moments of a path a fault is injected at, as fractions of the path's nominal time
CAMPAIGN_MOMENTS = (0.2, 0.45, 0.7)
#: one fault class per reduced run (system tests, on the ellipse: 24 s nominal, room for several)
FAULT_CLASSES = {
    "camera": "camera_freeze@3+5;camera_stop@10+4;occlude@16+4;frame_drop@21+4,rate=0.5",
    "link": "ble_loss@3+4,rate=0.8;unplug@10+2",
    "process": "kill:tracker_node@3;kill:planner_node@9;sigstop:bridge_node@14+3;kill:recorder@18;"
               "kill:camera_sim@21",
    "time": "clock_stall@5+3;sigstop:tracker_node@10+4",
    "emergency": "emergency@6",
    "dead_node": "kill:tracker_node@4,restart=no",
}


def campaign_plan(faults, moments, seeds, paths, path_times):
    """[(path, seed, Fault at its moment)] of the full campaign; ``path_times`` = {path: nominal s}."""
    plan = []
    for path in paths:
        for text in faults:
            base = parse_faults(text)[0]
            for m in moments:
                for seed in seeds:
                    plan.append((path, seed, replace(base, at=round(m * path_times[path], 1))))
    return plan


# -- metrics of one run --------------------------------------------------------------------------
@dataclass
class Observed:
    """What the twin's watch node saw (sim-time stamps [s]), independent of the recorder."""

    odom: list = field(default_factory=list)          # stamps of frog/odom
    decisions: list = field(default_factory=list)     # (stamp, primitive name) of frog/primitive
    fired: list = field(default_factory=list)         # stamps of frog/limb_activation (the robot fired)
    status: list = field(default_factory=list)        # (stamp, state) of frog/planner/status


def restart_windows(restarts, stamps, discovery: float) -> list:
    """[(t0, t1)]: from each restart time t0 to ``discovery`` s after the first of ``stamps`` after it
    (inf if none): how long a subscriber may not have matched a restarted publisher yet."""
    out = []
    for t0 in restarts:
        later = [t for t in stamps if t > t0]
        out.append((t0, (min(later) if later else float("inf")) + discovery))
    return out


class Resubscription:
    """Per topic, how long a restarted subscriber (the recorder) had not subscribed again.

    A restarted recorder records a topic only once it has found it in the graph and subscribed,
    seconds after its start under load (a series run: 2.4 s wall after its first log line, 5 s
    simulated after the restart). Only an endpoint the graph did not show before counts: a
    SIGKILLed recorder's subscriptions stay in the graph until their lease ends.
    """

    def __init__(self, topics):
        self.known = {t: set() for t in topics}     # endpoint gids seen on each topic
        self.waiting = {}                           # topic: restart time, no new subscription yet
        self.windows = {t: [] for t in topics}      # topic: [(restart, new subscription seen)]

    def restarted(self, t: float) -> None:
        for topic in self.known:
            self.waiting.setdefault(topic, t)       # restarted again before subscribing: the first

    def seen(self, t: float, topic: str, gids) -> None:
        """The graph at ``t`` shows the subscriber's endpoints ``gids`` (hashable) on ``topic``."""
        new = set(gids) - self.known[topic]
        self.known[topic] |= new
        if new and topic in self.waiting:
            self.windows[topic].append((self.waiting.pop(topic), t))

    def gaps(self, discovery: float) -> dict:
        """{topic: [(t0, t1)]}: from each restart to ``discovery`` s after the new subscription
        appeared (its publishers match it after their own discovery); inf while it has not."""
        out = {t: [(a, b + discovery) for a, b in w] for t, w in self.windows.items()}
        for topic, t0 in self.waiting.items():
            out[topic].append((t0, float("inf")))
        return out


def recovery_time(status, t_start: float, t_end: float, window: float, following: int = 1,
                  goal: int = 2, gap: float = 2.2) -> float | None:
    """Simulated s from ``t_end`` until the planner follows again; 0 if it was never blocked; None if never.

    The planner is blocked by the fault if a status in [t_start, t_end + window] is neither
    following nor goal reached (``window``: how long a fault takes to show, e.g. the stale
    bound), or if no status came for longer than ``gap`` there (a dead or starved planner
    says nothing; it decides every 1.43 s). Recovery is the first following (or goal)
    status after the first blocked moment.
    """
    rows = sorted(status)
    if not rows:
        return None
    lo, hi = t_start, min(t_end + window, rows[-1][0])     # the run's end is no silence
    blocked = [t for t, s in rows if lo <= t <= hi and s not in (following, goal)]
    times = [lo] + [t for t, _ in rows if lo < t <= hi]
    silent = [a for a, b in zip(times, times[1:] + [hi]) if b - a > gap]
    first = min(blocked[:1] + silent[:1], default=None)
    if first is None:
        return 0.0
    for t, s in rows:
        if t > first and s in (following, goal):
            return max(0.0, t - t_end)
    return None


def recorder_losses(seen: dict, recorded: dict, up_intervals, margin: float = 1.0, excluded=None) -> dict:
    """Per topic, the messages the watch saw while the recorder was up that the MCAP lacks.

    ``seen`` / ``recorded``: {topic: [stamp]}; ``up_intervals``: [(t0, t1)] in the same
    clock, the recorder's subscriptions live; a message within ``margin`` of an interval's
    ends is not counted (discovery and the kill are not instantaneous), nor one inside an
    ``excluded[topic]`` interval (a restarted node's first seconds, before DDS has matched
    its new publishers with the recorder: the recorder never saw those messages).
    """
    excluded = excluded or {}

    def expected(topic, s):
        return (any(a + margin <= s <= b - margin for a, b in up_intervals)
                and not any(a <= s <= b for a, b in excluded.get(topic, ())))

    out = {}
    for topic, stamps in seen.items():
        have = set(round(s, 6) for s in recorded.get(topic, ()))
        want = [s for s in stamps if expected(topic, s)]
        missing = [s for s in want if round(s, 6) not in have]
        out[topic] = {"expected": len(want), "lost": len(missing), "first_lost": missing[:3]}
    return out


def outcome(goal: bool, stop_reason, stale: int, lost: int, unclean) -> str:
    """completed (goal reached) / stopped (cleanly, for a stated reason) / failed."""
    if stale or lost or unclean:
        return "failed"
    if goal:
        return "completed"
    return "stopped" if stop_reason else "failed"


def fault_end(fault: Fault, nominal_end: float, ran: list) -> float:
    """When a fault ended, in the run's simulated clock, from the times its injector actions ran.

    A fault undone by an action (a camera live again, a SIGCONT, a clock running again) ended
    when that action ran, which for wall-timed faults is the only measure. A fault that one
    action starts and a node times itself (camera_sim's occluder, for ``duration`` simulated
    s) ended ``duration`` after that action. Nothing ran (the run ended first): its nominal end.
    """
    if not ran:
        return nominal_end
    if len(ran) == 1 and fault.duration and fault.kind not in WALL_DURATION:
        return ran[0] + fault.duration
    return max(ran)


def fault_report(faults, observer, sim_start: float, injector, recorded: dict, pulse_ages, goal: bool,
                 stop_reason, unclean) -> dict:
    """The fault section of a run's metrics: outcome, pulses on stale state, recorder losses, recovery.

    ``pulse_ages``: the recording's :class:`~frog_twin.core.state_audit.PulseAges` (the state
    behind every pulse, by publish times and by the bridge's own record)."""
    obs = observer.obs
    shifted = [replace(f, at=f.at + sim_start) for f in faults]
    # the recorded poses judge a pulse only while the recorder was up (1 s margins: its subscriptions)
    pulse_ages.complete = [(a + 1.0, b) for a, b in observer.recorder_up if b > a + 1.0]
    stale = pulse_ages.stale()
    gaps = observer.discovery_gaps()
    losses = recorder_losses(observer.seen, recorded, observer.recorder_up, excluded=gaps)
    deaf = getattr(observer, "recorder_deaf", ())
    unready = getattr(observer, "recorder_unready", ())
    lost = sum(v["lost"] for v in losses.values())
    per_fault = []
    window = pulse_ages.bound_s + 2.0          # how long a fault takes to show in the planner's state
    for f, g in zip(faults, shifted):
        ran = [t for t, _, what in injector.done if what.startswith(f.label() + ":")] if injector else []
        t_end = fault_end(f, g.end, ran)
        rec = None if f.kind == "emergency" else recovery_time(obs.status, g.at, t_end, window)
        per_fault.append({"fault": f.label(), "end_s": t_end - sim_start, "recovery_s": rec})
    return {"outcome": outcome(goal, stop_reason, len(stale), lost, unclean),
            "stop_reason": None if goal else stop_reason,
            "stale_pulses": stale, "pulse_ages": pulse_ages.summary(), "n_firings": len(obs.fired),
            "state_bound_s": pulse_ages.bound_s,
            "observed": {"decisions": obs.decisions, "fired": obs.fired, "n_odom": len(obs.odom)},
            "last_firing_s": max(obs.fired) - sim_start if obs.fired else None,
            "recorder": losses, "recorder_lost": lost,
            "recorder_up": observer.recorder_up, "discovery_gaps": gaps, "per_fault": per_fault,
            # the recorder alive but recording nothing (killed and restarted), or restarted and never ready
            # (killed as hung, or exited, before it said it subscribed): not up, so not checked;
            # what it did not record meanwhile is said
            "recorder_deaf": [(t0 - sim_start, t1 - sim_start, topic) for t0, t1, topic in deaf],
            "recorder_unready": [(t0 - sim_start, t1 - sim_start) for t0, t1 in unready],
            "recorder_deaf_missed": sum(v["lost"] for v in recorder_losses(
                observer.seen, recorded, [(t0, t1) for t0, t1, _ in deaf] + list(unready), margin=0.0).values()),
            "actions": [(t - sim_start, what) for t, _, what in injector.done] if injector else [],
            "injector_failures": injector.failures() if injector else [], "unclean_stops": list(unclean)}
