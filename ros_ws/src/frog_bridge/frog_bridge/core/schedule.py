"""Turn primitives and direct limb commands into timed ``h`` pulses, safely.

A primitive becomes up to two pulses: the front pair now, the rear pair one pulse length
later (the authors' executor sleeps one pulse between the two lines, also when the front
pair is empty). A new command cancels a pending pulse of an older one only if they
overlap: they share a limb and their heating intervals intersect (the newer command
wins; the limb is not heated twice back to back). Every command is checked whole by the
:class:`~frog_bridge.core.protection.LimbGuard` (a primitive is executed entirely or not
at all, so a refusal never turns a straight stroke into a turn), and nothing fires on a stale
state: every command carries the stamp of the state it was decided on
(:func:`frog_common.state_age.command_state`), a command whose state would be older than
``max_state_age_s`` when its last pulse is due is refused whole, and a pending pulse whose
state has grown older than that by its write is dropped, never written later.

Times are seconds on one clock chosen by the caller (the node's clock).
"""

from __future__ import annotations

import itertools
import math
from collections import Counter
from dataclasses import dataclass, field

from frog_common.primitives import PRIMITIVE_NAMES, limb_label
from frog_common.state_age import command_state, state_age_problem

from .limbs import primitive_pairs
from .protection import LimbGuard, PlannedPulse

# Reasons a command or pulse is not written (counter keys, also in diagnostics).
REFUSED_INTERVAL = "interval"
REFUSED_DUTY = "duty_cycle"
REFUSED_STATE_AGE = "state_age"      # the state behind the command is older than max_state_age_s
REFUSED_INVALID = "invalid"
REFUSED_LINK = "link_not_ready"
REFUSED_STALLED = "link_stalled"
REFUSED_EMERGENCY = "emergency"
CANCELLED_OVERLAP = "overlap_cancelled"
CANCELLED_LINK = "link_lost_cancelled"
CANCELLED_EMERGENCY = "emergency_cancelled"
CANCELLED_SHUTDOWN = "shutdown_cancelled"
CANCELLED_WATCHDOG = "watchdog_cancelled"     # no primitive for primitive_timeout_s (core.watchdog)


@dataclass(frozen=True)
class TimedPulse:
    """A pulse to write at ``due``; ``label`` says where it comes from (for logs); ``state``: the
    stamp of the state its command was decided on."""

    due: float
    limbs: tuple[int, ...]
    duration: float
    label: str
    command_id: int
    state: float

    def planned(self) -> PlannedPulse:
        return PlannedPulse(self.due, self.limbs, self.duration)


@dataclass
class Decision:
    """Outcome of a submission: the pulses scheduled, or why none were."""

    pulses: list[TimedPulse] = field(default_factory=list)
    cancelled: list[TimedPulse] = field(default_factory=list)
    refused: str | None = None          # a REFUSED_* key
    reason: str = ""                    # human-readable

    @property
    def accepted(self) -> bool:
        return self.refused is None


class CommandScheduler:
    """Pending pulses, ordered by due time, with protection and staleness checks.

    Parameters
    ----------
    guard : LimbGuard
        The per-limb limits (it also keeps the history of written pulses).
    pulse_s : float
        Heating pulse length [s] (what ``p`` sets).
    max_state_age_s : float
        A command whose state would be older than this when its last pulse is due is refused;
        a pulse whose state is older than this when it is written is dropped.
    """

    def __init__(self, guard: LimbGuard, pulse_s: float, max_state_age_s: float):
        if not pulse_s > 0:
            raise ValueError(f"pulse_s {pulse_s!r} must be > 0")
        if not max_state_age_s > 0:
            raise ValueError(f"max_state_age_s {max_state_age_s!r} must be > 0")
        self.guard = guard
        self.pulse_s = pulse_s
        self.max_state_age_s = max_state_age_s
        self.pending: list[TimedPulse] = []
        self.counts: Counter[str] = Counter()
        self._ids = itertools.count(1)

    # -- submissions ------------------------------------------------------------------
    def _state_problem(self, state: float, now: float, last_due: float) -> str | None:
        """Why a command on ``state`` may not fire: too old at its last pulse, or stamped ahead."""
        if state > now + self.max_state_age_s:
            return state_age_problem(now - state, self.max_state_age_s)
        return state_age_problem(last_due - state, self.max_state_age_s)

    def submit_primitive(self, primitive_id: int, stamp: float, now: float, state_stamp: float = 0.0) -> Decision:
        """Schedule primitive ``primitive_id`` (0-8) chosen at ``stamp`` on the state ``state_stamp``
        (0 = unset: :func:`~frog_common.state_age.command_state`)."""
        try:
            front, rear = primitive_pairs(primitive_id)
        except ValueError as exc:
            return self._refuse(REFUSED_INVALID, str(exc))
        name = PRIMITIVE_NAMES[primitive_id]
        state = command_state(state_stamp, stamp, now)
        problem = self._state_problem(state, now, now + (self.pulse_s if rear else 0.0))
        if problem:
            return self._refuse(REFUSED_STATE_AGE, f"primitive {name}: {problem}")
        cid = next(self._ids)
        pulses = []
        if front:
            pulses.append(TimedPulse(now, front, self.pulse_s, f"{name} front", cid, state))
        if rear:
            pulses.append(TimedPulse(now + self.pulse_s, rear, self.pulse_s, f"{name} rear", cid, state))
        return self._schedule(pulses, f"primitive {name}")

    def submit_limbs(self, limbs, stamp: float, now: float, pulse_s: float = 0.0, state_stamp: float = 0.0) -> Decision:
        """Schedule one pulse of ``limbs`` now (a direct limb command from a tool).

        ``pulse_s`` is the pulse length the sender asks for: 0 means the bridge's own; any
        other value must equal it (the relay has one pulse length, set once with ``p``).
        ``stamp`` and ``state_stamp`` as for :meth:`submit_primitive`.
        """
        # NaN compares False with everything: test finiteness first, or NaN passes as "close"
        if not math.isfinite(pulse_s) or pulse_s < 0.0:
            return self._refuse(REFUSED_INVALID, f"limb command pulse_duration {pulse_s!r} s is not a finite "
                                                 f"length >= 0 (send 0 for the bridge's pulse {self.pulse_s:g} s)")
        if pulse_s and abs(pulse_s - self.pulse_s) > 5e-4:
            return self._refuse(REFUSED_INVALID, f"limb command pulse_duration {pulse_s!r} s differs from the "
                                                 f"bridge's pulse {self.pulse_s:g} s (set once with 'p'; send 0 "
                                                 f"or change pulse_ms)")
        limbs = tuple(limbs)
        if not limbs or len(set(limbs)) != len(limbs) or any(i not in (0, 1, 2, 3) for i in limbs):
            return self._refuse(REFUSED_INVALID, f"limb ids {list(limbs)} must be distinct, in 0-3, "
                                                 f"at least one (FL 0, FR 1, BL 2, BR 3)")
        state = command_state(state_stamp, stamp, now)
        problem = self._state_problem(state, now, now)
        if problem:
            return self._refuse(REFUSED_STATE_AGE, f"limb command {limb_label(limbs)}: {problem}")
        cid = next(self._ids)
        pulse = TimedPulse(now, limbs, self.pulse_s, f"limbs {limb_label(limbs)}", cid, state)
        return self._schedule([pulse], f"limb command {limb_label(limbs)}")

    def _refuse(self, key: str, reason: str) -> Decision:
        self.counts[key] += 1
        return Decision(refused=key, reason=reason)

    def _schedule(self, pulses: list[TimedPulse], what: str) -> Decision:
        if not pulses:
            return Decision()
        cancelled = [p for p in self.pending if any(_overlaps(p, n) for n in pulses)]
        keep = [p for p in self.pending if p not in cancelled]
        problem = self.guard.check([p.planned() for p in pulses], [p.planned() for p in keep])
        if problem:
            key = REFUSED_DUTY if "max_duty_cycle" in problem else REFUSED_INTERVAL
            return self._refuse(key, f"{what} refused: {problem}")
        self.counts[CANCELLED_OVERLAP] += len(cancelled)
        self.pending = sorted(keep + pulses, key=lambda p: p.due)
        return Decision(pulses=pulses, cancelled=cancelled)

    # -- execution --------------------------------------------------------------------
    def next_due(self) -> float | None:
        return self.pending[0].due if self.pending else None

    def pop_due(self, now: float) -> tuple[list[TimedPulse], list[TimedPulse]]:
        """Pulses due by ``now``: ``(to_write, stale)``; a pulse whose state is older than
        ``max_state_age_s`` now (a late timer, a stopped process) is stale: dropped and counted."""
        due = [p for p in self.pending if p.due <= now]
        self.pending = [p for p in self.pending if p.due > now]
        stale = [p for p in due if now - p.state > self.max_state_age_s]
        self.counts[REFUSED_STATE_AGE] += len(stale)
        return [p for p in due if p not in stale], stale

    def written(self, pulse: TimedPulse, at: float) -> None:
        """``pulse`` was written at ``at`` (recorded for the limits)."""
        self.guard.record(PlannedPulse(at, pulse.limbs, pulse.duration))

    def cancel_all(self, key: str) -> list[TimedPulse]:
        """Drop every pending pulse (link lost, emergency, stop, watchdog, shutdown); count under ``key``."""
        dropped, self.pending = self.pending, []
        self.counts[key] += len(dropped)
        return dropped

    def count_refusal(self, key: str) -> None:
        self.counts[key] += 1


def _overlaps(a: TimedPulse, b: TimedPulse) -> bool:
    if a.command_id == b.command_id or not set(a.limbs) & set(b.limbs):
        return False
    return a.due < b.due + b.duration and b.due < a.due + a.duration
