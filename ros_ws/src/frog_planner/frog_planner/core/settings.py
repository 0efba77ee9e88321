"""The planner's settings, defined once: defaults, ranges, units and descriptions.

``planner_node`` declares its ROS parameters from these dataclasses, ``frog-planner-eval``
and the main job build their command-line options from them, and the planner is built
from an instance, so a setting has one default and one range everywhere.

Each field is a frog_common ``setting()`` (read by :func:`add_arguments` and by
soft_robot_common's ``params_from_dataclass``): ``live`` marks what is safe to change
while the planner runs; ``flags`` are extra command-line spellings kept for compatibility.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from dataclasses import dataclass

from frog_common.settings import Settings, describe, from_params, setting

from .paths import path_from_spec
from .transition_model import LOOKUPS
from .tree_search import MAX_DEPTH, CostWeights

PATH_TYPES = ("line", "sine", "ellipse", "waypoints")


@dataclass(frozen=True)
class PlannerSettings(Settings):
    """How the planner decides (seed 000, Algorithm 1 and eq. 19, plus this project's options)."""

    period: float = setting(1.5, "primitive period T (between library samples, transitions are interpolated)",
                             min=0.05, max=10.0, unit="s")
    depth: int = setting(2, "tree search depth H (the paper found 1 best on hardware; with stage_cost 2 is best in "
                          "the twin)", min=1, max=MAX_DEPTH, live=True)
    metric: str = setting("euclidean", "nearest-neighbour metric: scaled euclidean (KD-tree) or the paper's "
                           "relative metric", choices=("euclidean", "relative"))
    k_neighbours: int = setting(1, "nearest library states averaged", min=1, max=64, flags=("--k",))
    lookup: str = setting("si", "nearest-state search: si (the state as it is) or authors_code (as the authors' "
                           "planner searched their library: its velocity columns in the simulator's frame, x right "
                           "and y forward, its yaw rate in deg/s; for replaying their runs)", choices=LOOKUPS)
    gradient_correction: bool = setting(True, "correct the nearest state's transitions to first order for the "
                                         "velocity difference (library-fitted slopes); false = the paper")
    w_distance: float = setting(8000.0, "eq. 19 weight w_a of the distance to the path (paper 500)", min=0.0,
                                 max=1e6, unit="1/m", live=True, flags=("--w-a",))
    w_heading: float = setting(100.0, "eq. 19 weight w_b of the heading error (paper 50)", min=0.0, max=1e6,
                               unit="1/rad", live=True, flags=("--w-b",))
    w_progress: float = setting(300.0, "eq. 19 weight w_c of (1 - progress)", min=0.0, max=1e6, live=True,
                                 flags=("--w-c",))
    heading_lookahead: float = setting(0.0, "heading error against the path this far ahead; 0 = the paper's "
                                        "path tangent at the closest point", min=0.0, max=1.0, unit="m", live=True)
    velocity_lookahead: float = setting(0.0, "cost each leaf pose extrapolated by its predicted velocities "
                                        "over this time; 0 = the paper (cost at the leaf)", min=0.0, max=10.0,
                                        unit="s", live=True)
    yaw_rate_weight: float = setting(0.0, "weight per rad/s of |predicted yaw rate - path curvature x speed| "
                                      "at the leaf; 0 = the paper", min=0.0, max=1e6, unit="s/rad", live=True,
                                      flags=("--w-r",))
    stage_cost: bool = setting(True, "cost a sequence at each of its period ends, summed (false: at its leaf "
                                "only, the paper); depth > 1", live=True)
    allow_no_action: bool = setting(False, "choose 'no action' while following; false: every period fires limbs "
                                     "until the goal (a cost weighing the distance far above the progress would "
                                     "otherwise wait on the path)", live=True)
    stall_speed: float = setting(0.002, "standing still (below this planar speed and 0.01 rad/s) short of the "
                                  "goal, never choose 'no action', which would wait forever; 0 = the paper",
                                  min=0.0, max=0.1, unit="m/s", live=True)

    @classmethod
    def paper(cls, **overrides) -> "PlannerSettings":
        """The paper's exact planner: eq. 19 at the leaf, tangent heading, nearest-state transitions."""
        values = {"heading_lookahead": 0.0, "velocity_lookahead": 0.0, "yaw_rate_weight": 0.0, "depth": 1,
                  "stage_cost": False, "allow_no_action": True,
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


@dataclass(frozen=True)
class PathSettings(Settings):
    """The reference path (eq. 15-17 or a waypoint CSV), placed in the world frame."""

    path_type: str = setting("line", "reference path: line, sine, ellipse (paper eq. 15-17) or waypoints",
                              choices=PATH_TYPES, live=True)
    path_length: float = setting(0.0, "path length/size; 0 = the paper's value for the path type", min=0.0,
                                 max=100.0, unit="m", live=True)
    path_start_x: float = setting(0.0, "path start x in the world frame", min=-1e3, max=1e3, unit="m", live=True)
    path_start_y: float = setting(0.0, "path start y in the world frame", min=-1e3, max=1e3, unit="m", live=True)
    path_heading: float = setting(0.0, "direction of the path at its start", min=-2 * math.pi, max=2 * math.pi,
                                  unit="rad", live=True)
    waypoint_file: str = setting("", "CSV with header x,y [m] in the world frame (path_type waypoints)", live=True)
    goal_tolerance: float = setting(0.03, "distance to the path's end that counts as reached", min=1e-4, max=1.0,
                                    unit="m", live=True)
    goal_lateral_tolerance: float = setting(0.0, "crossing the finish line (normal at the path's end) counts "
                                             "only this close to the end along that line; 0 = goal_tolerance",
                                             min=0.0, max=1.0, unit="m", live=True)

    def cross_check(self) -> str | None:
        if self.path_type == "waypoints" and not self.waypoint_file:
            return "path_type waypoints needs waypoint_file (CSV with columns x,y in m)"
        return None

    def build(self):
        """The :class:`~frog_planner.core.paths.Path` (raises ValueError/OSError for a bad waypoint file)."""
        kw = {"goal_tolerance": self.goal_tolerance, "goal_lateral_tolerance": self.goal_lateral_tolerance or None}
        if self.path_length > 0 and self.path_type != "waypoints":
            kw["length"] = self.path_length
        return path_from_spec(self.path_type, start=(self.path_start_x, self.path_start_y),
                              heading=self.path_heading, waypoint_file=self.waypoint_file or None, **kw)


def add_arguments(parser: argparse.ArgumentParser, cls, exclude=()) -> None:
    """Add one command-line option per field of ``cls`` (``--w-distance``; ``flags`` as aliases)."""
    group = parser.add_argument_group(f"{cls.__name__} (defaults, ranges and units from frog_planner.core.settings)")
    for f in dataclasses.fields(cls):
        if f.name in exclude:
            continue
        md = f.metadata
        lo, hi = md["min"], md["max"]
        text = describe(f)
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
    return from_params(cls, vars(args), **overrides)
