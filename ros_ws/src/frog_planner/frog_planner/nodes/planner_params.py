"""planner_node's parameter table and its cross-checks (the planner's and the path's settings come
from :mod:`frog_planner.core.settings`, the state-age bound from :mod:`frog_common.state_age`)."""
from __future__ import annotations

from soft_robot_common import Param, params_from_dataclass

from frog_common.settings import from_params
from frog_common.state_age import StateAgeSettings
from frog_planner.core.settings import PathSettings, PlannerSettings

TRANSITIONS = ("library", "simulator")
SIMULATOR_MAX_DEPTH = 2

NODE_PARAMS = [
    Param("library_file", "", "motion-primitive library (.npz, docs/motion_library_format.md); live: set it "
          "(again) to load a new or fixed file", live=True),
    Param("odom_topic", "frog/odom", "odometry input (tracker, or the simulator's ground truth); relative "
          "names resolve in the node's namespace"),
    Param("state_topic", "frog/tracker/state", "the tracker's state per frame (TrackerState): the capture stamp of "
          "the measurement behind each odometry message, which decisions rest on; empty = the odometry's stamps "
          "are its measurements' (a simulator, a motion-capture system)"),
    Param("world_frame", "tank", "frame of the path and the status poses"),
] + params_from_dataclass(StateAgeSettings) + [
    Param("autostart", True, "start following at once (else wait for ~/start)"),
    Param("feasibility_lookahead", 0.1, "the status compares the path's tightest bend this far ahead with the "
          "frog's tightest steady turn (path_too_tight)", min=0.0, max=10.0, live=True),
    Param("transitions", "library", "predictions the search chains: library (the paper) or simulator "
          "(rollouts of the DER from the estimated state, frog/rollouts; depth 1-2)", choices=TRANSITIONS,
          live=True),
    Param("rollout_service", "frog/rollouts", "the simulator's rollout service (transitions simulator)"),
    Param("sent_topic", "frog/bridge/sent", "what the bridge fired (LimbActivation): the limbs' firing ages in "
          "the rollouts' start state"),
    Param("decision_deadline", 0.7, "transitions simulator: the decision is executed this many periods after "
          "the tick (the rollouts start from the state predicted then); a later response falls back to the "
          "library for that decision", min=0.05, max=0.95, live=True),
    Param("reanchor", True, "transitions simulator: decide at the deadline on the newest tracked state, the "
          "rollouts' tree chained from it; false: on the tick's state and the rollouts' prediction of the lead "
          "(needs max_state_age_s above the deadline)", live=True),
    Param("beam_width", 0, "transitions simulator, depth 2: roll out only the first primitives the library "
          "ranks best, this many; 0 = all 9", min=0, max=9, live=True),
    Param("replan_interval", 0.0, "> 0: the authors' asynchronous loop: decide this often [s] on the mean of the "
          "states since the last decision, and publish the newest decision at each period tick (they averaged "
          "9 tracker states, about 0.63 s); 0 = decide at the tick on the newest state", min=0.0, max=10.0),
    Param("initial_progress", 0.0, "progress along the path to start from, in [0, 1] (a restarted planner "
          "resumes where it was)", min=0.0, max=1.0),
]
PLANNER_PARAMS = params_from_dataclass(PlannerSettings)
PATH_PARAMS = params_from_dataclass(PathSettings)
PARAMS = NODE_PARAMS + PLANNER_PARAMS + PATH_PARAMS


def check_settings(values: dict) -> str | None:
    """Cross-checks of a candidate parameter set (ranges are checked per parameter)."""
    try:
        from_params(PathSettings, values)
        planner = from_params(PlannerSettings, values)
    except ValueError as exc:
        return str(exc)
    simulator = values.get("transitions") == "simulator"
    bound = values.get("max_state_age_s", StateAgeSettings().max_state_age_s)
    if simulator and values.get("replan_interval", 0.0) > 0:
        return "replan_interval (the authors' asynchronous loop) goes with transitions library only"
    if simulator and planner.depth > SIMULATOR_MAX_DEPTH:
        return (f"transitions simulator rolls out depth 1-{SIMULATOR_MAX_DEPTH}; depth is {planner.depth} "
                f"(lower depth, or use transitions library)")
    deadline = values.get("decision_deadline", 0.7) * planner.period
    if simulator and not values.get("reanchor", True) and bound <= deadline:
        return (f"reanchor false decides on the tick's state {deadline:.2f} s later, older than max_state_age_s "
                f"{bound:g} s: every decision would be refused (reanchor true, or a larger max_state_age_s)")
    if values.get("replan_interval", 0.0) >= bound:
        return (f"replan_interval {values['replan_interval']:g} s is not below max_state_age_s {bound:g} s: most "
                f"queued decisions would rest on a state too old to fire (raise max_state_age_s by the interval "
                f"to run the authors' loop)")
    return None
