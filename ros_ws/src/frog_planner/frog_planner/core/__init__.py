"""Pure-Python core of frog_planner: no rclpy imports, unit-tested without ROS.

Modules: ``transition_model`` (nearest-neighbour transitions of the motion library, which
``frog_common.motion_library_file`` reads), ``prediction`` (eq. 18), ``tree_search`` (eq. 19, Algorithm 1),
``paths`` (eq. 15-17, waypoints) and ``planner`` (one decision per period).
"""

from .paths import (Path, ellipse_path, line_path, parametric_path, path_from_spec, sinusoid_path,
                    waypoint_path_from_csv)
from .planner import CostTerms, Decision, Planner
from .prediction import apply_transition, predict_world_state
from .transition_model import TransitionModel
from .tree_search import CostWeights, PathCost, SearchResult, path_cost, search

__all__ = [
    "Path", "ellipse_path", "line_path", "parametric_path", "path_from_spec", "sinusoid_path",
    "waypoint_path_from_csv",
    "CostTerms", "Decision", "Planner",
    "apply_transition", "predict_world_state",
    "TransitionModel",
    "CostWeights", "PathCost", "SearchResult", "path_cost", "search",
]
