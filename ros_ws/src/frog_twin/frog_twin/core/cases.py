"""The paths a planner is evaluated on, placed in the tank: the paper's three and the robot's own.

One definition for the twin (``frog-twin``), the planner comparison (``--planner-compare``) and
the in-process evaluator (``frog-planner-eval``), so a path, its start pose, its decision
period and its time limit mean the same in each.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from frog_planner.core.settings import PathSettings

from . import replay

PATH_NAMES = ("line", "sine", "ellipse")
#: The paths run along the tank's +y, the long side of the overhead camera's view
#: (frog_vision's default camera: 0.8 m above the origin, image right = tank +y), centred on
#: the view so the robot stays in the picture.
PATH_HEADING = math.pi / 2
#: Simulated time allowed for a hardware path: this many times the real run's duration, plus
#: REPLAY_EXTRA_S.
REPLAY_DURATION_FACTOR = 2.0
REPLAY_EXTRA_S = 15.0


@dataclass(frozen=True)
class Case:
    """One path to follow: name, path settings, start pose (x, y [m], heading [rad]; None: the
    path's start), decision period [s] and time limit [s] (None: the caller's)."""

    name: str
    path_settings: PathSettings
    start_pose: tuple | None
    period: float
    duration: float | None = None


def placed_path_settings(path_settings: PathSettings, name: str) -> PathSettings:
    """``path_settings`` for path ``name``, rotated to PATH_HEADING and centred on the tank origin."""
    local = dataclasses.replace(path_settings, path_type=name, path_start_x=0.0, path_start_y=0.0,
                                path_heading=PATH_HEADING)
    pts = local.build().points
    centre = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
    return dataclasses.replace(local, path_start_x=float(-centre[0]), path_start_y=float(-centre[1]))


def path_start_pose(path_settings: PathSettings, lateral_offset: float = 0.0) -> tuple:
    """On the path's start, along its tangent, ``lateral_offset`` m to its left."""
    path = path_settings.build()
    h0 = float(path.tangent_headings[0])
    x0 = path.points[0] + lateral_offset * np.array([-math.sin(h0), math.cos(h0)])
    return float(x0[0]), float(x0[1]), h0


def paper_cases(path_settings: PathSettings, period: float, names=PATH_NAMES) -> list[Case]:
    """The paper's paths (eq. 15-17), placed in the tank, started on the path."""
    return [Case(name, placed_path_settings(path_settings, name), None, period) for name in names]


def hardware_cases(runs_folder: Path | str, waypoint_folder: Path | str,
                   path_settings: PathSettings = PathSettings()) -> list[Case]:
    """Each hardware run's reference path as waypoints (written to ``waypoint_folder``), from the
    run's logged start pose, at its fitted decision period, for twice its duration + 15 s."""
    folder = Path(waypoint_folder)
    folder.mkdir(parents=True, exist_ok=True)
    cases = []
    for run_csv, path_csv in replay.find_runs(runs_folder):
        setup = replay.replay_setup(run_csv, path_csv)
        waypoints = replay.write_waypoints(setup.path, folder / f"{setup.name}_waypoints.csv")
        ps = dataclasses.replace(path_settings, path_type="waypoints", waypoint_file=str(waypoints))
        cases.append(Case(setup.name, ps, setup.start_pose, setup.period,
                          REPLAY_DURATION_FACTOR * float(setup.time[-1]) + REPLAY_EXTRA_S))
    return cases
