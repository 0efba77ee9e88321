"""What planner_node says after each period: the fields of its status and of its diagnostics.

Plain values (no messages): the node copies them into ``soft_robot_interfaces/PlannerStatus``
and its ``diagnostics``. Cost terms are unweighted (eq. 19 term divided by its weight); a
term whose weight is 0 is NaN (unknown), not a made-up 0.
"""
from __future__ import annotations

import math

from .decision_loop import ERROR, FOLLOWING, GOAL_REACHED, IDLE, DecisionLoop, Outcome
from .feasibility import feasibility_at

NAN = math.nan
STATE_NAMES = ("idle", "following", "goal_reached", "waiting", "error")


def status_fields(out: Outcome, loop: DecisionLoop, weights, path, limits, lookahead: float) -> dict:
    """PlannerStatus fields (but the header) of outcome ``out`` of ``loop``; ``predicted_pose`` as (x, y, theta)."""
    pid, name = out.primitive
    f = {"primitive_id": pid, "primitive_name": name, "state": out.state, "message": out.message,
         "total_cost": NAN, "cost_distance": NAN, "cost_heading": NAN, "cost_progress": NAN,
         "distance_to_path": NAN, "predicted_pose": (NAN, NAN, NAN), "state_age": loop.state_age(),
         "path_progress": float(loop.planner.progress) if loop.planner is not None else 0.0}
    d = out.decision if out.state == FOLLOWING else None
    if d is not None:
        t = d.cost_terms
        f.update(total_cost=float(d.total_cost), distance_to_path=float(d.distance_to_path),
                 cost_distance=t.distance / weights.distance if weights.distance else NAN,
                 cost_heading=t.heading / weights.heading if weights.heading else NAN,
                 cost_progress=t.progress / weights.progress if weights.progress else NAN,
                 predicted_pose=tuple(float(v) for v in d.predicted_pose))
    limit, ahead, tight = feasibility_at(path, limits, f["path_progress"], lookahead)
    f.update(turn_radius_limit=limit, path_radius_ahead=ahead, path_too_tight=tight)
    if tight and out.state == FOLLOWING:
        f["message"] = (f"{out.message}; the path ahead bends at r {ahead * 100:.1f} cm, tighter than the frog's "
                        f"{limit * 100:.1f} cm turn: cutting")
    return f


def loop_report(loop: DecisionLoop, path_name: str):
    """(level, message, values) of the node's diagnostics: ERROR without a usable library, WARN while
    waiting for a state, else OK; ``ready`` once a library is loaded."""
    blocked = loop.blocked()
    state = FOLLOWING if blocked is None else blocked[0]
    level = 0 if state in (FOLLOWING, IDLE, GOAL_REACHED) else 2 if state == ERROR else 1
    message = f"following the {path_name} path" if blocked is None else blocked[1]
    planner = loop.planner
    return level, message, {
        "path": path_name, "progress": float(planner.progress) if planner is not None else 0.0,
        "state": STATE_NAMES[state], "waited_decisions": loop.waited, "state_age_s": loop.state_age(),
        "max_state_age_s": loop.settings.max_state_age_s, "transitions": loop.settings.transitions,
        "simulator_decisions": loop.simulator_decisions, "fallback_decisions": loop.fallback_decisions,
        "ready": planner is not None}
