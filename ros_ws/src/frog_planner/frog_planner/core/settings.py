"""The planner's settings, defined once: defaults, ranges, units and descriptions.

``planner_node`` declares its ROS parameters from these dataclasses, ``frog-planner-eval``
and the main job build their command-line options from them, and the planner is built
from an instance, so a setting has one default and one range everywhere.

Field metadata (read by :func:`add_arguments` and by soft_robot_common's
``params_from_dataclass``): ``description``, ``range`` (inclusive; None = open),
``unit``, ``choices``, ``live`` (safe to change while the planner runs) and ``flags``
(extra command-line spellings kept for compatibility).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from dataclasses import dataclass, field

from .paths import path_from_spec
from .transition_model import LOOKUPS
from .tree_search import MAX_DEPTH, CostWeights

PATH_TYPES = ("line", "sine", "ellipse", "waypoints")


def _setting(default, description, range=(None, None), unit="", live=False, choices=None, flags=()):
    md = {"description": description, "range": range, "unit": unit, "live": live, "flags": tuple(flags)}
    if choices is not None:
        md["choices"] = tuple(choices)
    return field(default=default, metadata=md)


@dataclass(frozen=True)
class PlannerSettings:
    """How the planner decides (seed 000, Algorithm 1 and eq. 19, plus this project's options)."""

    period: float = _setting(1.5, "primitive period T (between library samples, transitions are interpolated)",
                             (0.05, 10.0), "s")
    depth: int = _setting(1, "tree search depth H (the paper found 1 best on hardware)", (1, MAX_DEPTH),
                          live=True)
    metric: str = _setting("euclidean", "nearest-neighbour metric: scaled euclidean (KD-tree) or the paper's "
                           "relative metric", choices=("euclidean", "relative"))
    k_neighbours: int = _setting(1, "nearest library states averaged", (1, 64), flags=("--k",))
    lookup: str = _setting("si", "nearest-state search: si (the state as it is) or authors_code (as the authors' "
                           "planner searched their library: its velocity columns in the simulator's frame, x right "
                           "and y forward, its yaw rate in deg/s; for replaying their runs)", choices=LOOKUPS)
    gradient_correction: bool = _setting(True, "correct the nearest state's transitions to first order for the "
                                         "velocity difference (library-fitted slopes); false = the paper")
    w_distance: float = _setting(500.0, "eq. 19 weight w_a of the distance to the path", (0.0, 1e6), "1/m",
                                 live=True, flags=("--w-a",))
    w_heading: float = _setting(50.0, "eq. 19 weight w_b of the heading error", (0.0, 1e6), "1/rad", live=True,
                                flags=("--w-b",))
    w_progress: float = _setting(300.0, "eq. 19 weight w_c of (1 - progress)", (0.0, 1e6), live=True,
                                 flags=("--w-c",))
    heading_lookahead: float = _setting(0.1, "heading error against the path this far ahead; 0 = the paper's "
                                        "path tangent at the closest point", (0.0, 1.0), "m", live=True)
    velocity_lookahead: float = _setting(1.5, "cost each leaf pose extrapolated by its predicted velocities "
                                         "over this time; 0 = the paper (cost at the leaf)", (0.0, 10.0), "s",
                                         live=True)
    yaw_rate_weight: float = _setting(0.0, "weight per rad/s of |predicted yaw rate - path curvature x speed| "
                                      "at the leaf; 0 = the paper", (0.0, 1e6), "s/rad", live=True,
                                      flags=("--w-r",))
    stall_speed: float = _setting(0.002, "standing still (below this planar speed and 0.01 rad/s) short of the "
                                  "goal, never choose 'no action', which would wait forever; 0 = the paper",
                                  (0.0, 0.1), "m/s", live=True)

    def __post_init__(self):
        reason = check(self)
        if reason:
            raise ValueError(reason)

    @classmethod
    def paper(cls, **overrides) -> "PlannerSettings":
        """The paper's exact planner: eq. 19 at the leaf, tangent heading, nearest-state transitions."""
        values = {"heading_lookahead": 0.0, "velocity_lookahead": 0.0, "yaw_rate_weight": 0.0,
                  "stall_speed": 0.0, "gradient_correction": False, "w_distance": 500.0, "w_heading": 50.0,
                  "w_progress": 300.0}
        values.update(overrides)
        return cls(**values)

    @property
    def weights(self) -> CostWeights:
        return CostWeights(self.w_distance, self.w_heading, self.w_progress)

    def model_kwargs(self) -> dict:
        """Keyword arguments of ``TransitionModel.load``."""
        return {"period": self.period, "metric": self.metric, "k": self.k_neighbours,
                "gradient_correction": self.gradient_correction, "lookup": self.lookup}

    def planner_kwargs(self) -> dict:
        """Keyword arguments of ``Planner`` (after the model and the path)."""
        return {"weights": self.weights, "depth": self.depth, "heading_lookahead": self.heading_lookahead,
                "velocity_lookahead": self.velocity_lookahead, "yaw_rate_weight": self.yaw_rate_weight,
                "stall_speed": self.stall_speed}


@dataclass(frozen=True)
class PathSettings:
    """The reference path (eq. 15-17 or a waypoint CSV), placed in the world frame."""

    path_type: str = _setting("line", "reference path: line, sine, ellipse (paper eq. 15-17) or waypoints",
                              choices=PATH_TYPES, live=True)
    path_length: float = _setting(0.0, "path length/size; 0 = the paper's value for the path type", (0.0, 100.0),
                                  "m", live=True)
    path_start_x: float = _setting(0.0, "path start x in the world frame", (-1e3, 1e3), "m", live=True)
    path_start_y: float = _setting(0.0, "path start y in the world frame", (-1e3, 1e3), "m", live=True)
    path_heading: float = _setting(0.0, "direction of the path at its start", (-2 * math.pi, 2 * math.pi), "rad",
                                   live=True)
    waypoint_file: str = _setting("", "CSV with header x,y [m] in the world frame (path_type waypoints)", live=True)
    goal_tolerance: float = _setting(0.03, "distance to the path's end that counts as reached", (1e-4, 1.0), "m",
                                     live=True)
    goal_lateral_tolerance: float = _setting(0.0, "crossing the finish line (normal at the path's end) counts "
                                             "only this close to the end along that line; 0 = goal_tolerance",
                                             (0.0, 1.0), "m", live=True)

    def __post_init__(self):
        reason = check(self)
        if reason:
            raise ValueError(reason)
        if self.path_type == "waypoints" and not self.waypoint_file:
            raise ValueError("path_type waypoints needs waypoint_file (CSV with columns x,y in m)")

    def build(self):
        """The :class:`~frog_planner.core.paths.Path` (raises ValueError/OSError for a bad waypoint file)."""
        kw = {"goal_tolerance": self.goal_tolerance, "goal_lateral_tolerance": self.goal_lateral_tolerance or None}
        if self.path_length > 0 and self.path_type != "waypoints":
            kw["length"] = self.path_length
        return path_from_spec(self.path_type, start=(self.path_start_x, self.path_start_y),
                              heading=self.path_heading, waypoint_file=self.waypoint_file or None, **kw)


def check(settings) -> str | None:
    """Why an instance's values are out of their declared range or choices, or None."""
    for f in dataclasses.fields(settings):
        value = getattr(settings, f.name)
        lo, hi = f.metadata.get("range", (None, None))
        if isinstance(value, float) and not math.isfinite(value):
            return f"{f.name} = {value!r} must be finite"
        if lo is not None and value < lo:
            return f"{f.name} = {value!r} is below its minimum {lo!r}"
        if hi is not None and value > hi:
            return f"{f.name} = {value!r} is above its maximum {hi!r}"
        choices = f.metadata.get("choices")
        if choices is not None and value not in choices:
            return f"{f.name} = {value!r} is not one of {', '.join(map(repr, choices))}"
    return None


def add_arguments(parser: argparse.ArgumentParser, cls, exclude=()) -> None:
    """Add one command-line option per field of ``cls`` (``--w-distance``; ``flags`` as aliases)."""
    group = parser.add_argument_group(f"{cls.__name__} (defaults, ranges and units from frog_planner.core.settings)")
    for f in dataclasses.fields(cls):
        if f.name in exclude:
            continue
        md = f.metadata
        lo, hi = md.get("range", (None, None))
        text = md["description"] + (f" [{md['unit']}]" if md.get("unit") else "")
        if lo is not None or hi is not None:
            text += f"; range {lo if lo is not None else '-inf'} to {hi if hi is not None else 'inf'}"
        text += f" (default {f.default!r})"
        names = ["--" + f.name.replace("_", "-"), *md.get("flags", ())]
        if f.type in (bool, "bool"):
            group.add_argument(*names, dest=f.name, action=argparse.BooleanOptionalAction, default=f.default,
                               help=text)
        else:
            kind = {"float": float, "int": int, "str": str}.get(f.type, f.type)
            group.add_argument(*names, dest=f.name, type=kind, default=f.default, help=text,
                               choices=md.get("choices"), metavar=None if md.get("choices") else f.name.upper())


def from_arguments(cls, args: argparse.Namespace, **overrides):
    """An instance of ``cls`` from the parsed options (``overrides`` win); ValueError if out of range."""
    values = {f.name: getattr(args, f.name) for f in dataclasses.fields(cls) if hasattr(args, f.name)}
    values.update(overrides)
    return cls(**values)


def as_dict(settings) -> dict:
    """``{field: value}`` of an instance (e.g. as ROS parameters for ``planner_node``)."""
    return {f.name: getattr(settings, f.name) for f in dataclasses.fields(settings)}
