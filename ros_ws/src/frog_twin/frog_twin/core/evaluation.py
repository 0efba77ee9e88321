"""Closed-loop evaluation in one process: DER simulator + library planner (paper Fig. 5, S3).

It joins frog_planner's planner core with frog_sim's simulator; the two cores stay
independent and meet here, in the composition package, as they meet in the ROS graph.
Every period T the planner sees the simulator's rigid-body state (ground truth), picks a
primitive, and the simulator executes it for T seconds.
"""

from __future__ import annotations

import json
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path as FsPath
from typing import Optional

import numpy as np

from frog_common.primitives import primitive_name
from frog_planner.core.paths import Path, ellipse_path, line_path, sinusoid_path
from frog_planner.core.planner import Planner
from frog_planner.core.settings import PlannerSettings
from frog_planner.core.transition_model import TransitionModel
from frog_planner.core.tree_search import tree_from_rows
from frog_sim.core.yaw_disturbance import TANK_YAW_TORQUE_SD

from .metrics import samples_before_finish  # noqa: F401  (re-exported for callers of this module)
from .realism import Realism

PATHS = {"line": line_path, "sine": sinusoid_path, "ellipse": ellipse_path}

#: Where the search's predictions come from: the motion library (the paper) or the simulator.
TRANSITION_SOURCES = ("library", "simulator")
#: What the simulator's rollouts start from: the robot's estimate (tracked pose, body twist and
#: the limbs' firing times: what planner_node sends rollout_node) or the simulator's full state
#: (limb shapes and node velocities included: exact for the nominal robot).
ROLLOUT_STARTS = ("estimated", "exact")

#: Deepest tree the simulator source expands (9^2 = 81 simulated periods per decision).
MAX_SIMULATOR_DEPTH = 2


class SimulatorTransitions:
    """The search's predictions from batched rollouts of the simulator (``frog_sim`` :class:`Rollouts`),
    as ``planner_node`` gets them from ``rollout_node`` with ``transitions: simulator``.

    Parameters
    ----------
    rollouts : frog_sim.core.rollouts.Rollouts
        The batched simulator (nominal model: a robot's limb strengths are not known to it).
    start : {'estimated', 'exact'}
        ``estimated``: the tree starts from the tracked pose, twist and firing times (what a
        robot knows); ``exact``: from the simulator's full state.
    lead : float
        Seconds from the observation to the decision's execution (planner_node's
        ``decision_deadline`` x period); the rollouts coast this long first.
    beam : int
        Depth 2: roll out only this many first primitives, best by the library (0: all).
    identify : bool
        Estimated start: learn the robot's limb strengths from its motion between decisions
        (:class:`~frog_sim.core.limb_identification.LimbIdentification`) and roll out with them.
    reanchor : bool
        Decide at the execution, on the pose tracked then, with the tree rolled out from the
        observation ``lead`` earlier chained from that pose (planner_node's ``reanchor``); false:
        decide on the observation's pose with the tree's own prediction of the lead.
    yaw_torque_sd : float
        With ``identify``: also estimate the tank's yaw torque, of this stationary sd [N m]
        (rollout_node's ``yaw_torque_sd``, and its default); 0: assume none.
    """

    def __init__(self, rollouts, start: str = "estimated", lead: float = 0.0, beam: int = 0,
                 identify: bool = False, reanchor: bool = False,
                 yaw_torque_sd: float = TANK_YAW_TORQUE_SD):
        if start not in ROLLOUT_STARTS:
            raise ValueError(f"rollout start {start!r} unknown; expected one of {ROLLOUT_STARTS}")
        if not (np.isfinite(lead) and 0.0 <= lead <= 5.0):
            raise ValueError(f"lead {lead!r} s must be in [0, 5]")
        if not 0 <= int(beam) <= 9:
            raise ValueError(f"beam {beam!r} must be in 0-9")
        if identify and start != "estimated":
            raise ValueError("limb identification learns from the estimated start; the exact start has none")
        self.rollouts, self.start, self.lead, self.beam = rollouts, start, float(lead), int(beam)
        self.reanchor = bool(reanchor)
        self.identification = None
        if identify:
            from frog_sim.core.limb_identification import LimbIdentification
            self.identification = LimbIdentification(rollouts, torque_sd=yaw_torque_sd)

    def reset(self) -> None:
        """A new run: the nominal robot, nothing learned."""
        self.rollouts.set_limb_strength(None)
        if self.identification is not None:
            self.identification.reset()

    def expander(self, sim, planner, pose, twist):
        """The expander for :meth:`Planner.decide` from this instant of ``sim`` (observed ``pose``,
        ``twist``): it chains the tree from the pose it is given (with ``reanchor``: the pose at
        the execution, ``lead`` later; else this one)."""
        depth = planner.depth
        if not 1 <= depth <= MAX_SIMULATOR_DEPTH:
            raise ValueError(f"simulator transitions support depth 1-{MAX_SIMULATOR_DEPTH}, not {depth}")
        ro = self.rollouts
        if self.start == "exact":
            start = ro.start_from_simulation(sim)
        elif self.identification is not None:
            start = self.identification.start(sim.time, pose, twist, sim.last_firings())
        else:
            start = ro.estimated_start(pose, twist, sim.last_firings(), now=sim.time)
        firsts = ()
        if depth == 2 and 0 < self.beam < planner.model.n_primitives:
            ranked = planner.rank_first_actions(pose, twist)
            firsts = [planner.model.primitive_names[i] for i in ranked[:self.beam]]
        rows, _ = ro.decision_tree(start, planner.settings.period, depth, self.lead, firsts,
                                   from_lead_end=self.reanchor)
        n = planner.model.n_primitives
        if self.reanchor:
            return lambda p, v, d: tree_from_rows(p, rows, d, n)
        return lambda p, v, d: tree_from_rows(start.pose, rows, d, n)


@dataclass
class ClosedLoopResult:
    """A closed-loop run (SI units): samples of the robot, decisions, metrics."""

    path: Path
    time: np.ndarray                 # (S,) s
    pose: np.ndarray                 # (S, 3) x m, y m, heading rad
    distance: np.ndarray             # (S,) distance of the COM to the path, m
    decisions: list = field(default_factory=list)   # dicts per period
    metrics: dict = field(default_factory=dict)


def run_closed_loop(path: Path, model: TransitionModel, settings: PlannerSettings = PlannerSettings(),
                    max_time: Optional[float] = None, start_offset=(0.0, 0.0, 0.0),
                    sim_params: Optional[dict] = None, sample_interval: float = 0.05,
                    simulation=None, transitions: str = "library", simulator: Optional[SimulatorTransitions] = None,
                    realism: Optional[Realism] = None, start_pose=None) -> ClosedLoopResult:
    """Follow ``path`` with the simulated frog until the goal or ``max_time``.

    Parameters
    ----------
    path : Path
    model : TransitionModel
        Built for ``period``.
    settings : PlannerSettings
        The planner's settings (depth, eq. 19 weights, look-aheads, stall speed; see
        :class:`~frog_planner.core.planner.Planner`) and the primitive period T [s].
    max_time : float, optional
        Give up after this long [s] (default: time to cover the path at 0.5 cm/s).
    start_offset : (float, float, float)
        Start pose relative to the path's start: along-track [m], lateral (left) [m],
        heading [rad], in the frame of the path's initial tangent.
    sim_params : dict, optional
        FrogParameters overrides for the simulator.
    simulation : FrogSimulation, optional
        Reuse a simulator (it is reset).
    transitions : {'library', 'simulator'}
        Predictions of the search: the motion library (the paper) or the simulator's batched
        rollouts (``simulator``; depth <= 2).
    simulator : SimulatorTransitions, optional
        How the rollouts start and how long they lead (default: the estimated start, no lead,
        a one-thread :class:`Rollouts` on the nominal model).
    realism : Realism, optional
        Make the simulated robot the twin's robot of that seed (limb strengths, kick spread,
        the tank's yaw torque); default the nominal robot.
    start_pose : (float, float, float), optional
        World start pose x, y [m], heading [rad] (instead of ``start_offset`` from the path's start).

    Returns
    -------
    ClosedLoopResult
    """
    from frog_sim.core.model_parameters import FrogParameters
    from frog_sim.core.simulation import FrogSimulation

    sim = simulation or FrogSimulation(FrogParameters().replace(**(sim_params or {})))
    sim.reset()
    if start_pose is None:
        h0 = float(path.tangent_headings[0])
        c, s = np.cos(h0), np.sin(h0)
        x0 = path.points[0] + start_offset[0] * np.array([c, s]) + start_offset[1] * np.array([-s, c])
        start_pose = (float(x0[0]), float(x0[1]), h0 + start_offset[2])
    sim.set_pose(*(float(v) for v in start_pose))
    limb_strength = realism.apply(sim) if realism is not None else sim.limb_strength
    if transitions not in TRANSITION_SOURCES:
        raise ValueError(f"transitions {transitions!r} unknown; expected one of {TRANSITION_SOURCES}")
    if transitions == "simulator":
        if not 1 <= settings.depth <= MAX_SIMULATOR_DEPTH:
            raise ValueError(f"simulator transitions support depth 1-{MAX_SIMULATOR_DEPTH}, not {settings.depth}")
        if simulator is None:
            from frog_sim.core.rollouts import Rollouts
            simulator = SimulatorTransitions(Rollouts(threads=1))
        simulator.reset()
    period = settings.period
    lead = simulator.lead if transitions == "simulator" else 0.0
    if lead >= period:
        raise ValueError(f"lead {lead} s must be shorter than the period {period} s")
    planner = Planner(model, path, settings)
    max_time = max_time or path.length / 0.005
    stride = int(round(sample_interval / sim.time_step))
    times, poses = [], []
    decisions = []
    goal_time = None
    decide_s = []

    def sample():
        st = sim.rigid_body_state()
        times.append(sim.time)
        poses.append([st.com[0], st.com[1], st.heading])
        return st

    def advance(until):
        while sim.time < until - 0.5 * sim.time_step:
            sim.step(max(1, min(stride, int(round((until - sim.time) / sim.time_step)))))
            sample()

    st = sample()
    k = 0
    while sim.time < max_time:
        st = sim.rigid_body_state()
        pose = [st.com[0], st.com[1], st.heading]
        twist = [st.body_velocity[0], st.body_velocity[1], st.yaw_rate]
        t0 = time.perf_counter()
        expander = simulator.expander(sim, planner, pose, twist) if transitions == "simulator" else None
        if expander is not None and simulator.reanchor:        # decide at the execution, on its pose
            advance(k * period + lead)
            st = sim.rigid_body_state()
            pose = [st.com[0], st.com[1], st.heading]
            twist = [st.body_velocity[0], st.body_velocity[1], st.yaw_rate]
        d = planner.decide(pose, twist, expander)
        decide_s.append(time.perf_counter() - t0)
        decisions.append({"time": sim.time, "primitive": d.name, "primitive_id": d.primitive_id,
                          "total_cost": d.total_cost, "yaw_rate_cost": d.yaw_rate_cost,
                          "progress": d.progress,
                          "distance_to_path": d.distance_to_path,
                          "current_cost": d.current_cost,
                          "current_terms": [d.current_cost_terms.distance, d.current_cost_terms.heading,
                                            d.current_cost_terms.progress],
                          "predicted_pose": d.predicted_pose.tolist()})
        if d.goal_reached:
            goal_time = sim.time
            break
        advance(k * period + lead)               # the decision is executed ``lead`` after its observation
        sim.execute_primitive(d.primitive_id)
        k += 1
        advance(k * period)
    t = np.array(times)
    pose = np.array(poses)
    n = samples_before_finish(pose[:, :2], path.points)
    t, pose = t[:n], pose[:n]
    dist = np.array([path.distance_to(p) for p in pose])
    counts = Counter(d["primitive"] for d in decisions if not (goal_time and d is decisions[-1]))
    progress = decisions[-1]["progress"] if decisions else 0.0
    end = goal_time if goal_time is not None else float(t[-1])
    metrics = {
        "path": path.name, "path_length_m": path.length, "depth": settings.depth, "period_s": period,
        "transitions": transitions,
        "metric": model.metric if transitions == "library" else f"simulator-{simulator.start}",
        "lead_s": lead, "limb_strength": limb_strength,
        "k_neighbours": model.k,
        "gradient_correction": model.gradient_correction, "heading_lookahead_m": settings.heading_lookahead,
        "velocity_lookahead_s": settings.velocity_lookahead, "yaw_rate_weight": settings.yaw_rate_weight,
        "stall_speed_m_per_s": settings.stall_speed,
        "weights": [settings.w_distance, settings.w_heading, settings.w_progress],
        "goal_reached": goal_time is not None,
        "completion_time_s": goal_time,
        "final_progress": progress,
        "mean_distance_m": float(dist.mean()), "max_distance_m": float(dist.max()),
        "mean_speed_along_path_m_per_s": float(progress * path.length / end) if end > 0 else 0.0,
        "primitives_used": dict(sorted(counts.items())),
        "decisions": len(decisions),
        "median_decision_latency_s": float(np.median(decide_s)) if decide_s else None,
    }
    return ClosedLoopResult(path, t, pose, dist, decisions, metrics)


@dataclass
class TurningResponse:
    """How the simulated frog turns under one primitive repeated every period, from rest (SI)."""

    primitive: str
    steady_radius: float        # m, circle fitted to the COM track over the last 40 % of the run
    steady_speed: float         # m/s, COM displacement per period / period over that part
    steady_yaw_rate: float      # rad/s, mean over that part
    rise_time: float            # s until the yaw rate first reaches 63 % of its steady value
    max_course_lag: float       # rad, largest |heading - direction of travel| while moving > 2 mm/s


def turning_response(primitive, period: float = 1.5, duration: float = 45.0, sim_params: Optional[dict] = None,
                     simulation=None) -> TurningResponse:
    """Repeat ``primitive`` every ``period`` from rest and measure the turn it settles into.

    The frog's square body has no keel: its heading turns well before its centre of mass
    changes course (side-slip), and the yaw rate builds up over many periods. A body-heading
    turn is therefore not a COM turn, and the radius of a steady circle says nothing about
    how quickly it can be reached; both numbers are reported.
    """
    from frog_sim.core.model_parameters import FrogParameters
    from frog_sim.core.simulation import FrogSimulation

    sim = simulation or FrogSimulation(FrogParameters().replace(**(sim_params or {})))
    sim.reset()
    steps = int(round(period / sim.time_step))
    stride = max(1, int(round(0.05 / sim.time_step)))
    t, com, yaw, lag = [], [], [], []
    for _ in range(int(np.ceil(duration / period))):
        sim.execute_primitive(primitive)
        for _ in range(0, steps, stride):
            sim.step(stride)
            st = sim.rigid_body_state()
            t.append(sim.time)
            com.append(st.com.copy())
            yaw.append(st.yaw_rate)
            if np.hypot(*st.body_velocity[:2]) > 0.002:
                lag.append(abs(np.arctan2(st.body_velocity[1], st.body_velocity[0])))
    t, com, yaw = np.array(t), np.array(com), np.array(yaw)
    late = t > 0.6 * t[-1]
    pts = com[late]
    # algebraic (Kasa) circle fit: |p|^2 = 2 c.p + k
    a = np.column_stack([2.0 * pts, np.ones(len(pts))])
    sol = np.linalg.lstsq(a, (pts ** 2).sum(axis=1), rcond=None)[0]
    radius = float(np.sqrt(sol[2] + sol[0] ** 2 + sol[1] ** 2))
    # speed from the displacement over whole periods: the COM wiggles within each kick
    lag_n = steps // stride
    speed = float(np.mean(np.hypot(*(pts[lag_n:] - pts[:-lag_n]).T)) / period)
    steady_yaw = float(yaw[late].mean())
    reached = np.nonzero(np.abs(yaw) >= 0.63 * abs(steady_yaw))[0] if steady_yaw != 0 else []
    rise = float(t[reached[0]]) if len(reached) else float("nan")
    sim.reset()
    name = primitive_name(primitive)
    return TurningResponse(name, radius, speed, steady_yaw, rise, float(max(lag)) if lag else 0.0)


def path_min_radius(path: Path) -> float:
    """Smallest radius of curvature of the path [m] (inf for a straight line)."""
    k = np.abs(path.curvature_at(np.linspace(0.0, 1.0, 2001)))
    return float(1.0 / k.max()) if k.max() > 0 else float("inf")


def plot_run(result: ClosedLoopResult, png) -> None:
    """Paper Fig. 5d-g (path over reference, distance vs time) and Fig. S3 (cost terms)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 3, figsize=(16, 4.8))
    ax = axes[0]
    ref = result.path.points
    ax.plot(ref[:, 0] * 100, ref[:, 1] * 100, "k--", lw=1.2, label="reference path")
    ax.plot(result.pose[:, 0] * 100, result.pose[:, 1] * 100, color="tab:blue", lw=1.5,
            label="robot (centre of mass)")
    dec = result.decisions
    if dec:
        pts = np.array([[d["time"], *d["predicted_pose"]] for d in dec])
        ax.plot(pts[:, 1] * 100, pts[:, 2] * 100, ".", color="tab:orange", ms=4,
                label="predicted next pose")
    ax.plot(*(ref[0] * 100), "go", label="start")
    ax.plot(*(ref[-1] * 100), "r*", ms=12, label="goal")
    ax.set_aspect("equal")
    ax.set(xlabel="x [cm]", ylabel="y [cm]", title=f"{result.path.name}: path following")
    ax.legend(fontsize=8)
    ax = axes[1]
    ax.plot(result.time, result.distance * 100)
    m = result.metrics
    ax.axhline(m["mean_distance_m"] * 100, ls="--", color="k",
               label=f"mean {m['mean_distance_m'] * 100:.2f} cm, max {m['max_distance_m'] * 100:.2f} cm")
    ax.set(xlabel="time [s]", ylabel="distance to path [cm]", title="tracking error")
    ax.legend(fontsize=8)
    ax = axes[2]
    if dec:
        t = [d["time"] for d in dec]
        terms = np.array([d["current_terms"] for d in dec])
        for j, name in enumerate(("w_a * distance", "w_b * heading error", "w_c * (1 - progress)")):
            ax.plot(t, terms[:, j], label=name)
        ax.plot(t, terms.sum(axis=1), "k", lw=1.5, label="total (eq. 19)")
    ax.set(xlabel="time [s]", ylabel="cost", title="cost terms at the measured pose")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(png, dpi=120)
    plt.close(fig)


def save_result(result: ClosedLoopResult, folder, stem: Optional[str] = None) -> dict:
    """Write ``<stem>.json`` (metrics + decisions), ``<stem>.png`` and ``<stem>.npz`` samples
    (default stem ``<path>_d<depth>_<metric>``)."""
    folder = FsPath(folder)
    folder.mkdir(parents=True, exist_ok=True)
    stem = stem or f"{result.path.name}_d{result.metrics['depth']}_{result.metrics['metric']}"
    np.savez(folder / f"{stem}.npz", time=result.time, pose=result.pose, distance=result.distance,
             path=result.path.points)
    (folder / f"{stem}.json").write_text(json.dumps(
        {"metrics": result.metrics, "decisions": result.decisions,
         "units": {"time": "s", "pose": ["m", "m", "rad"], "distance": "m"}}, indent=1))
    plot_run(result, folder / f"{stem}.png")
    return {"json": str(folder / f"{stem}.json"), "png": str(folder / f"{stem}.png")}
