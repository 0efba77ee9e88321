"""The planner node's decision loop without ROS: the state gate, the three loops, the deadlines.

Every period tick the loop either decides (FOLLOWING, with the stamp of the state the decision
rests on) or says why not (IDLE, GOAL_REACHED, WAITING, ERROR; the node publishes primitive I
then). It never decides on a state older than ``max_state_age_s``: the state is the capture
stamp of the measurement behind the newest odometry (:mod:`.state_stamps`), checked at the tick
and again when the decision is ready. Three loops:

- at the tick, on the newest state (the default);
- ``replan_interval`` > 0: the authors' published control code: every ``replan_interval`` a
  decision on the mean of the states since the previous one (:mod:`.state_window`), queued;
  each tick executes the newest queued decision once (none new: I);
- ``transitions`` simulator: the tick asks for rollouts (:class:`RolloutRequest`, sent by the
  node) and the decision is made at the deadline, ``decision_deadline`` periods later, on the
  rollouts if they came in time (chained from the newest state with ``reanchor``) and on the
  library otherwise (a fallback, counted).

Times are seconds on the node's clock, read through ``clock()`` (a fake clock in the tests).
The state codes are ``soft_robot_interfaces/PlannerStatus``'s (checked by the node tests).
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Callable

from frog_common.primitives import NO_ACTION, PRIMITIVE_IDS
from frog_common.state_age import state_age_problem

from .state_stamps import StateSample, StateStamps
from .state_window import StateWindow

IDLE, FOLLOWING, GOAL_REACHED, WAITING, ERROR = range(5)


@dataclass(frozen=True)
class Outcome:
    """What one tick (or deadline) gives: the state, why, and the decision when FOLLOWING."""

    state: int
    message: str
    decision: object = None                  # frog_planner.core.planner.Decision when FOLLOWING
    state_stamp: float | None = None         # the measurement the decision rests on [s]
    logs: tuple = ()                         # (severity, text) pairs: a state or reason that changed

    @property
    def primitive(self) -> tuple[int, str]:
        """(id, name) to publish: the decision's, or I."""
        if self.state == FOLLOWING and self.decision is not None and not self.decision.goal_reached:
            return self.decision.primitive_id, self.decision.name
        return PRIMITIVE_IDS[NO_ACTION], NO_ACTION


@dataclass(frozen=True)
class RolloutRequest:
    """The simulator's rollouts to ask for at a tick; the decision follows at ``deadline`` [s]."""

    sample: StateSample
    depth: int
    lead: float              # from the pose's stamp to the decision's execution [s]
    first_primitives: tuple  # depth 2 with a beam: the library's best first primitives
    deadline: float


@dataclass
class LoopSettings:
    """The loop's own settings (planner_node's parameters of the same names)."""

    period: float
    max_state_age_s: float
    replan_interval: float = 0.0
    transitions: str = "library"
    decision_deadline: float = 0.7     # periods
    reanchor: bool = True
    beam_width: int = 0

    @classmethod
    def from_params(cls, values: dict, period: float) -> "LoopSettings":
        """From the node's parameters of the same names (``max_state_age_s``, ...) and the period."""
        names = ("max_state_age_s", "replan_interval", "transitions", "decision_deadline", "reanchor", "beam_width")
        return cls(period, **{k: values[k] for k in names})


class DecisionLoop:
    """See the module docstring. ``source`` names the odometry input in the WAITING messages."""

    def __init__(self, settings: LoopSettings, clock: Callable[[], float], paired: bool = False,
                 source: str = "odometry", autostart: bool = True):
        self.settings = settings
        self.clock = clock
        self.source = source
        self.states = StateStamps(paired)
        self.window = StateWindow()              # replan_interval: the states since the last decision
        self.planner = None
        self.library_error: str | None = "no library loaded"
        self.running = autostart
        self.goal_reached = False
        self.queued = None                       # replan_interval: (decision, state stamp, n)
        self.pending: RolloutRequest | None = None
        self.waited = 0                          # ticks refused for a missing or too old state
        self.simulator_decisions = 0
        self.fallback_decisions = 0
        self._last_fallback = None
        self._logged = None

    # -- inputs ---------------------------------------------------------------------------------
    def odometry(self, pose, twist, stamp: float) -> None:
        for s in self.states.odometry(pose, twist, stamp):
            self.window.add(s.pose, s.twist)

    def tracker_state(self, stamp: float, state_stamp: float | None) -> None:
        for s in self.states.tracker_state(stamp, state_stamp):
            self.window.add(s.pose, s.twist)

    def set_planner(self, planner, error: str | None = None) -> None:
        """The planner to decide with (keeps nothing of the old one), or the reason there is none."""
        self.planner, self.library_error = planner, error if planner is None else None

    def start(self) -> str | None:
        """~/start: follow (from the start again after the goal); the reason it cannot, or None."""
        if self.library_error:
            return self.library_error
        if self.goal_reached:
            self.planner.reset()
            self.goal_reached = False
        self.window.clear()
        self.queued = None
        self.running = True
        return None

    def stop(self) -> None:
        self.running = False

    # -- the gate -------------------------------------------------------------------------------
    def state_age(self, now: float | None = None) -> float:
        """Age of the newest state [s] (NaN before the first)."""
        s = self.states.newest
        return math.nan if s is None else (self.clock() if now is None else now) - s.state_stamp

    def blocked(self, now: float | None = None) -> tuple[int, str] | None:
        """(state, reason) when no decision may be made now, else None."""
        if self.library_error:
            return ERROR, self.library_error
        if not self.running:
            return IDLE, "stopped (call ~/start)"
        if self.goal_reached:
            return GOAL_REACHED, "goal reached"
        if self.states.newest is None:
            what = (f"{self.source} with the tracker's state for it" if self.states.paired else self.source)
            return WAITING, f"no {what} yet"
        problem = state_age_problem(self.state_age(now), self.settings.max_state_age_s)
        return (WAITING, problem) if problem else None

    # -- ticks ----------------------------------------------------------------------------------
    def tick(self) -> Outcome | RolloutRequest:
        """The period tick: a decision, a refusal, or a rollout request (transitions simulator)."""
        if self.pending is not None:             # a deadline the clock skipped past: close it first
            self.finish(None, "the deadline passed unseen")
        blocked = self.blocked()
        if blocked is not None:
            return self._refuse(*blocked)
        if self.settings.transitions == "simulator":
            return self._request()
        if self.settings.replan_interval > 0:
            return self._execute_queued()
        sample = self.states.newest
        try:
            d = self.planner.decide(sample.pose, sample.twist)
        except ValueError as exc:
            return self._refuse(ERROR, f"planner rejected the state: {exc}")
        # checked again with the decision ready: on a loaded machine a state at the bound passes it meanwhile
        blocked = self.blocked()
        return self._refuse(*blocked) if blocked else self._act(d, sample.state_stamp, "following")

    def replan(self) -> str | None:
        """replan_interval: decide on the mean of the states since the last decision and queue it;
        returns why the planner rejected the mean, if it did."""
        if self.blocked() is not None:
            self.window.clear()                  # stopped or stale: nothing old goes into a later mean
            self.queued = None
            return None
        if self.window.count == 0:
            return None
        pose, twist, n = self.window.mean()
        self.window.clear()
        try:
            d = self.planner.decide(pose, twist)
        except ValueError as exc:
            return f"planner rejected the mean state: {exc}"
        self.queued = (d, self.states.newest.state_stamp, n)
        return None

    def _execute_queued(self) -> Outcome:
        if self.queued is None:
            return self._refuse(WAITING, "no new decision queued since the last tick (replan_interval)")
        (d, state_stamp, n), self.queued = self.queued, None
        problem = state_age_problem(self.clock() - state_stamp, self.settings.max_state_age_s)
        if problem:
            return self._refuse(WAITING, f"the queued decision's {problem}")
        return self._act(d, state_stamp, f"following (queued decision on the mean of {n} states)")

    # -- transitions simulator ------------------------------------------------------------------
    def _request(self) -> RolloutRequest:
        s = self.settings
        sample = self.states.newest
        firsts = ()
        model = self.planner.model
        if self.planner.depth == 2 and 0 < s.beam_width < model.n_primitives:
            ranked = self.planner.rank_first_actions(sample.pose, sample.twist)
            firsts = tuple(model.primitive_names[i] for i in ranked[:s.beam_width])
        deadline = self.clock() + s.decision_deadline * s.period
        self.pending = RolloutRequest(sample, self.planner.depth, max(0.0, deadline - sample.stamp), firsts,
                                      deadline)
        return self.pending

    def finish(self, expander, reason: str | None) -> Outcome | None:
        """At the deadline: decide on the rollouts' ``expander`` if they came, else on the library
        (``reason`` says why not; a fallback, logged once per reason and counted)."""
        req, self.pending = self.pending, None
        if req is None:
            return None
        blocked = self.blocked()
        if blocked is not None:
            return self._refuse(*blocked)
        reanchor = self.settings.reanchor
        sample = self.states.newest if (expander is None or reanchor) else req.sample
        problem = state_age_problem(self.clock() - sample.state_stamp, self.settings.max_state_age_s)
        if problem:
            return self._refuse(WAITING, f"the rollouts' {problem}")
        try:
            if expander is not None:
                d = self.planner.decide(sample.pose, sample.twist, expander)
                self.simulator_decisions += 1
                self._last_fallback = None
                return self._act(d, sample.state_stamp, f"following (simulator, depth {req.depth}, lead "
                                                        f"{req.lead:.4f} s)")
            d = self.planner.decide(sample.pose, sample.twist)
        except ValueError as exc:
            return self._refuse(ERROR, f"planner rejected the state: {exc}")
        self.fallback_decisions += 1
        log = None
        if reason != self._last_fallback:
            log = ("warn", f"library decision instead of the simulator's: {reason} ({self.fallback_decisions} "
                           f"so far)")
        self._last_fallback = reason
        out = self._act(d, sample.state_stamp, f"following (library fallback: {reason})")
        return Outcome(out.state, out.message, out.decision, out.state_stamp, out.logs + ((log,) if log else ()))

    # -- outcomes -------------------------------------------------------------------------------
    def _act(self, d, state_stamp: float, note: str) -> Outcome:
        if d.goal_reached:
            self.goal_reached = True
            message = f"goal reached (progress {d.progress:.3f}, {d.distance_to_path * 100:.2f} cm from the path)"
            return Outcome(GOAL_REACHED, message, d, state_stamp, self._log(GOAL_REACHED, message))
        logs = self._log(FOLLOWING, f"following the {self.planner.path.name} path")
        return Outcome(FOLLOWING, note, d, state_stamp, logs)

    def _refuse(self, state: int, reason: str) -> Outcome:
        if state == WAITING:
            self.waited += 1
        return Outcome(state, reason, logs=self._log(state, reason))

    def _log(self, state: int, message: str) -> tuple:
        """((severity, text),) once per state and reason (the ages in a reason do not count)."""
        key = (state, re.sub(r"-?\d+(\.\d+)?", "#", message))
        if key == self._logged:
            return ()
        self._logged = key
        text = message if state == FOLLOWING else message + "; publishing primitive I"
        return (({ERROR: "error", WAITING: "warn"}.get(state, "info"), text),)
