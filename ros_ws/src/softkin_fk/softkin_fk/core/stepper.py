"""Cable pull <-> stepper position, soft limits and synchronised moves of the tendon motors.

Each cable winds on a pulley of radius r on a stepper motor (seed 001, Sec. V-C): a pull p
(m of cable drawn in from rest) turns the motor by p / r rad, i.e.
``p / (2 pi r) * steps_per_rev * microsteps`` microsteps. The Marlin board counts an axis in
its own units, ``steps_per_unit`` microsteps per unit (its M92 setting), so the axis value the
driver writes is ``steps / steps_per_unit``. Positions are quantised to whole microsteps.

A move to new pulls takes ``max |dp_j| / max_cable_speed`` (the fastest cable at the speed
limit); Marlin moves all axes along a straight line in axis space at the feedrate F (axis
units per minute, along the line's length), so ``F = 60 * |d axis| / duration`` makes all
three cables arrive together.
"""
from __future__ import annotations

import dataclasses
import math
from typing import List, Optional, Tuple

import numpy as np


@dataclasses.dataclass
class CableMotorMap:
    """Conversion and limits for one set of tendon motors (all lengths in metres).

    Attributes
    ----------
    joints : list of str
        Cable (joint) names, e.g. ``['cable_0', 'cable_1', 'cable_2']``.
    axes : list of str
        Marlin axis letter per joint (X, Y, Z or E).
    pulley_radius : float
        Radius the cable winds on [m].
    steps_per_rev : int
        Full steps per motor revolution (200 for 1.8 deg motors).
    microsteps : int
        Driver microstepping (16 on a RAMPS A4988 with all jumpers).
    steps_per_unit : float
        The board's microsteps per axis unit (M92).
    min_pull, max_pull : float
        Soft limits of every cable's pull [m]: below min_pull the cable would be pushed slack,
        beyond max_pull it leaves the model's range.
    max_cable_speed : float
        Speed of the fastest cable in a move [m/s].
    max_feedrate : float
        Cap on the feedrate [axis units / min]; a move that would need more takes longer.
    """

    joints: List[str] = dataclasses.field(default_factory=lambda: ['cable_0', 'cable_1', 'cable_2'])
    axes: List[str] = dataclasses.field(default_factory=lambda: ['X', 'Y', 'Z'])
    pulley_radius: float = 0.005
    steps_per_rev: int = 200
    microsteps: int = 16
    steps_per_unit: float = 80.0
    min_pull: float = 0.0
    max_pull: float = 0.0085
    max_cable_speed: float = 0.01
    max_feedrate: float = 6000.0

    def problem(self) -> Optional[str]:
        """Why this configuration cannot work, or None."""
        if len(self.joints) != len(self.axes) or not self.joints:
            return f"joints {self.joints} and axes {self.axes} must have the same, non-zero length"
        if len(set(self.axes)) != len(self.axes) or not set(self.axes) <= set('XYZE'):
            return f"axes {self.axes} must be distinct letters among X, Y, Z, E"
        if len(set(self.joints)) != len(self.joints):
            return f"joints {self.joints} must be distinct"
        if not self.min_pull < self.max_pull:
            return f"min_pull {self.min_pull} must be below max_pull {self.max_pull}"
        for name in ('pulley_radius', 'steps_per_unit', 'max_cable_speed', 'max_feedrate'):
            if not getattr(self, name) > 0:
                return f"{name} = {getattr(self, name)} must be positive"
        if self.steps_per_rev < 1 or self.microsteps < 1:
            return f"steps_per_rev {self.steps_per_rev} and microsteps {self.microsteps} must be >= 1"
        return None

    @property
    def steps_per_metre(self) -> float:
        """Microsteps per metre of cable: steps_per_rev * microsteps / (2 pi r)."""
        return self.steps_per_rev * self.microsteps / (2.0 * math.pi * self.pulley_radius)

    def pull_to_steps(self, pulls) -> np.ndarray:
        """Whole microsteps (int64) for cable pulls [m]."""
        return np.rint(np.asarray(pulls, float) * self.steps_per_metre).astype(np.int64)

    def steps_to_pull(self, steps) -> np.ndarray:
        return np.asarray(steps, float) / self.steps_per_metre

    def steps_to_axis(self, steps) -> np.ndarray:
        """Axis values (board units) of microstep counts."""
        return np.asarray(steps, float) / self.steps_per_unit

    def axis_to_steps(self, values) -> np.ndarray:
        return np.rint(np.asarray(values, float) * self.steps_per_unit).astype(np.int64)

    def limit_problem(self, pulls) -> Optional[str]:
        """Why these pulls are refused (soft limits, NaN), or None."""
        p = np.asarray(pulls, float)
        if p.shape != (len(self.joints),):
            return f"{p.size} pulls for {len(self.joints)} cables"
        if not np.all(np.isfinite(p)):
            return f"pulls {p.tolist()} are not finite"
        for j, v in zip(self.joints, p):
            if v < self.min_pull - 1e-12:
                return f"{j} pull {v * 1e3:.4f} mm is below min_pull {self.min_pull * 1e3:.4f} mm (slack cable)"
            if v > self.max_pull + 1e-12:
                return f"{j} pull {v * 1e3:.4f} mm exceeds max_pull {self.max_pull * 1e3:.4f} mm (model range)"
        return None

    def move(self, from_steps, to_steps) -> Tuple[dict, float, float]:
        """A synchronised move: ({axis: value}, feedrate [units/min], duration [s]).

        Returns an empty dict (and zeros) when no motor moves.
        """
        a = np.asarray(from_steps, np.int64)
        b = np.asarray(to_steps, np.int64)
        if np.array_equal(a, b):
            return {}, 0.0, 0.0
        d_pull = np.abs(self.steps_to_pull(b - a))
        d_axis = float(np.linalg.norm(self.steps_to_axis(b - a)))
        duration = float(d_pull.max()) / self.max_cable_speed
        feed = 60.0 * d_axis / duration
        if feed > self.max_feedrate:
            feed = self.max_feedrate
            duration = 60.0 * d_axis / feed
        values = {ax: float(v) for ax, v in zip(self.axes, self.steps_to_axis(b))}
        return values, feed, duration
