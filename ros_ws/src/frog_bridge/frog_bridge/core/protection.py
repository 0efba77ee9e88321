"""Limb protection: a limit on how often and how long each SMA limb is heated.

An SMA limb that is reheated before its nitinol wire has cooled does not relax, so it
gives no stroke, and repeated heating without cooling degrades the shape-memory response
(seed 000, "Actuator Characterization"; Section 2.2). Two limits, both per limb:

- ``min_limb_interval_s``: at most one pulse start per interval (cooling before reheat);
- ``max_duty_cycle``: heated time / ``duty_window_s`` over any window ending at the end of
  the new pulse (the mean heating power the limb can shed).

How the defaults follow from the measured curvature profiles is documented in the
package README (frog_bridge/README.md, "Limb protection") and in :data:`DEFAULTS`.
"""

from __future__ import annotations

import itertools
from collections import deque
from dataclasses import dataclass

from frog_common.primitives import LIMB_NAMES
from frog_common.settings import Settings, setting

_EPS = 1e-9


@dataclass(frozen=True)
class ProtectionConfig(Settings):
    """Per-limb heating limits (bridge_node's parameters of the same names)."""

    min_limb_interval_s: float = setting(0.8, "shortest time between two pulses of one limb (10 vol% EGaIn "
                                         "limbs: 1.2 Hz max)", min=0.0, max=60.0, unit="s")
    max_duty_cycle: float = setting(0.10, "largest heated fraction of any duty_window_s, per limb",
                                    min=0.001, max=1.0)
    duty_window_s: float = setting(10.0, "window of the duty-cycle bound", min=0.1, max=3600.0, unit="s")


# Defaults for the authors' hardware (10 vol% EGaIn limbs, 80 ms pulses): the fastest cycle
# these limbs were characterised at is 1.2 Hz (0.83 s; limb_curvature_profiles.csv), their
# curvature is 90 % recovered 0.53-0.75 s after the pulse starts; 1.2 Hz x 80 ms = 9.6 % duty.
DEFAULTS = ProtectionConfig()


@dataclass(frozen=True)
class PlannedPulse:
    """One ``h`` line: limbs heated from ``start`` for ``duration`` seconds."""

    start: float
    limbs: tuple[int, ...]
    duration: float


class LimbGuard:
    """Remembers the pulses written per limb and refuses pulses that break the limits."""

    def __init__(self, config: ProtectionConfig = DEFAULTS):
        self.config = config              # checked when it was built
        self._history: dict[int, deque[tuple[float, float]]] = {i: deque() for i in range(len(LIMB_NAMES))}

    def last_start(self, limb: int) -> float | None:
        h = self._history[limb]
        return h[-1][0] if h else None

    def clear(self) -> None:
        for h in self._history.values():
            h.clear()

    def check(self, pulses: list[PlannedPulse], others: list[PlannedPulse] = ()) -> str | None:
        """Why ``pulses`` (checked together) may not be written, or None if they may.

        ``others`` are pulses already scheduled but not yet written; they count like
        history.
        """
        cfg = self.config
        interval, window = cfg.min_limb_interval_s, cfg.duty_window_s
        placed: list[PlannedPulse] = list(others)
        for p in pulses:
            end = p.start + p.duration
            w0 = end - window
            for limb in p.limbs:
                extra = [(q.start, q.duration) for q in placed if limb in q.limbs]
                heated = p.duration
                for s, d in itertools.chain(self._history[limb], extra):    # one pass: both limits
                    gap = abs(p.start - s)
                    if gap + _EPS < interval:
                        return (f"limb {LIMB_NAMES[limb]} was heated {gap:.3f} s before "
                                f"(min_limb_interval_s {interval:g} s)")
                    if s + d > w0 and s < end:
                        heated += min(end, s + d) - max(w0, s)
                duty = heated / window
                if duty > cfg.max_duty_cycle + _EPS:
                    return (f"limb {LIMB_NAMES[limb]} would be heated {duty * 100:.1f} % of the last "
                            f"{window:g} s (max_duty_cycle {cfg.max_duty_cycle * 100:g} %)")
            placed.append(p)
        return None

    def record(self, pulse: PlannedPulse) -> None:
        """A pulse was written at ``pulse.start``; forget pulses older than every limit.

        A start earlier than the last recorded one means the clock jumped back (a simulator
        reset); the history is then meaningless and is cleared first.
        """
        keep = max(self.config.duty_window_s, self.config.min_limb_interval_s) + pulse.duration
        if any(h and pulse.start < h[-1][0] - 1.0 for h in self._history.values()):
            self.clear()
        for limb in pulse.limbs:
            h = self._history[limb]
            h.append((pulse.start, pulse.duration))
            while h and h[0][0] < pulse.start - keep:
                h.popleft()
