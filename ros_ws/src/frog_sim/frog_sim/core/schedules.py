"""Limb activation schedules: gaits and the nine motion primitives.

A schedule is just the list of firing times of each limb. Limb names and ids follow
the robot's serial protocol (DESIGN.md): FL 0, FR 1, BL 2, BR 3.

* **Gait** (paper "Results"): the front pair fires at ``n / f``, the rear pair at
  ``(n + phase_offset) / f``; phase offset = delay between front and rear firing over
  the cycle time.
* **Primitives** (the table in ``frog_common.primitives``): the front limbs of the
  primitive fire first, the rear limbs one pulse later (pulse 80 ms); one primitive per
  period (1.5 s).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from frog_common.primitives import LIMB_IDS, LIMB_NAMES, REAR_LIMBS, primitive_limbs


@dataclass
class ActivationSchedule:
    """Firing times [s] of each limb.

    Examples
    --------
    >>> s = ActivationSchedule.gait(1.0, 0.5, duration=2.0)
    >>> s.times('FL').tolist(), s.times('BR').tolist()
    ([0.0, 1.0], [0.5, 1.5])
    """

    firing_times: dict

    def __post_init__(self):
        clean = {}
        for limb in LIMB_NAMES:
            t = np.sort(np.asarray(self.firing_times.get(limb, []), dtype=float).ravel())
            if t.size and not np.all(np.isfinite(t)):
                raise ValueError(f'firing times of limb {limb} contain a non-finite value')
            clean[limb] = t
        unknown = set(self.firing_times) - set(LIMB_NAMES)
        if unknown:
            raise ValueError(f'unknown limb name(s) {sorted(unknown)}; expected {LIMB_NAMES}')
        self.firing_times = clean

    @classmethod
    def empty(cls) -> 'ActivationSchedule':
        """No limb ever fires."""
        return cls({})

    def times(self, limb: str) -> np.ndarray:
        """Sorted firing times of ``limb`` [s]."""
        if limb not in LIMB_IDS:
            raise ValueError(f'unknown limb {limb!r}; expected one of {LIMB_NAMES}')
        return self.firing_times[limb]

    def per_limb(self) -> list[np.ndarray]:
        """Firing times in limb-id order (FL, FR, BL, BR)."""
        return [self.firing_times[l] for l in LIMB_NAMES]

    def merged(self, other: 'ActivationSchedule') -> 'ActivationSchedule':
        """Union of two schedules."""
        return ActivationSchedule({l: np.concatenate([self.times(l), other.times(l)]) for l in LIMB_NAMES})

    def shifted(self, offset: float) -> 'ActivationSchedule':
        """Same schedule ``offset`` seconds later."""
        return ActivationSchedule({l: self.times(l) + offset for l in LIMB_NAMES})

    def end_time(self) -> float:
        """Last firing time (or -inf if empty) [s]."""
        all_t = np.concatenate(self.per_limb())
        return float(all_t.max()) if all_t.size else -np.inf

    @classmethod
    def gait(cls, frequency_hz: float, phase_offset: float, duration: float,
             start: float = 0.0, limbs=LIMB_NAMES) -> 'ActivationSchedule':
        """Periodic gait: front pair at ``start + n/f``, rear pair ``phase_offset/f`` later.

        Parameters
        ----------
        frequency_hz : float
            Actuation frequency f > 0 [Hz].
        phase_offset : float
            Rear delay as a fraction of the cycle, in [0, 1).
        duration : float
            Fire every cycle that starts before ``start + duration`` [s].
        limbs : iterable of str
            Limbs that take part (default all four; e.g. ('FL', 'BL') for one side).

        Raises
        ------
        ValueError
            On a non-positive frequency or a phase outside [0, 1).
        """
        if not (np.isfinite(frequency_hz) and frequency_hz > 0):
            raise ValueError(f'gait frequency {frequency_hz!r} Hz must be > 0')
        if not 0.0 <= phase_offset < 1.0:
            raise ValueError(f'phase offset {phase_offset!r} must be in [0, 1)')
        period = 1.0 / frequency_hz
        n = int(np.ceil(duration / period - 1e-9))
        base = start + period * np.arange(max(n, 0))
        times = {}
        for limb in limbs:
            if limb not in LIMB_IDS:
                raise ValueError(f'unknown limb {limb!r}; expected one of {LIMB_NAMES}')
            times[limb] = base + (phase_offset * period if limb in REAR_LIMBS else 0.0)
        return cls(times)

    @classmethod
    def primitive(cls, primitive, start: float = 0.0, pulse: float = 0.080) -> 'ActivationSchedule':
        """One primitive (id 0-8 or 'A'-'I'): its front limbs at ``start``, rear at ``start + pulse``."""
        front, rear = primitive_limbs(primitive)
        times = {l: [start] for l in front}
        times.update({l: [start + pulse] for l in rear})
        return cls(times)

    @classmethod
    def primitive_sequence(cls, primitives, period: float = 1.5, pulse: float = 0.080,
                           start: float = 0.0) -> 'ActivationSchedule':
        """Primitives executed one per ``period`` seconds from ``start``."""
        if not (period > 0 and pulse > 0):
            raise ValueError(f'period {period!r} s and pulse {pulse!r} s must be > 0')
        sched = cls.empty()
        for k, p in enumerate(primitives):
            sched = sched.merged(cls.primitive(p, start + k * period, pulse))
        return sched
