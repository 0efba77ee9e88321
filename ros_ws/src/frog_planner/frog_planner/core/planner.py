"""Receding-horizon primitive planner (paper seed 000, Algorithm 1): one decision per period.

The planner keeps one piece of state, the progress along the path, which only moves
forward: each decision searches the path a window ahead of the previous progress.
A ROS node or an evaluator calls :meth:`Planner.decide` once per period T and sends
``Decision.primitive_id``; :class:`Decision` carries everything a status message needs.
"""

from dataclasses import dataclass

import numpy as np

from .settings import PlannerSettings
from .tree_search import path_cost, search
from frog_common.se2 import world_to_body


@dataclass(frozen=True)
class CostTerms:
    """The weighted terms of eq. 19 (dimensionless cost units).

    Attributes
    ----------
    distance : float
        w_a * distance to path.
    heading : float
        w_b * |heading error| (rad).
    progress : float
        w_c * (1 - progress).
    """

    distance: float
    heading: float
    progress: float

    @classmethod
    def from_array(cls, terms):
        """From an array of shape (3,)."""
        return cls(float(terms[0]), float(terms[1]), float(terms[2]))


@dataclass(frozen=True)
class Decision:
    """One planner decision.

    Attributes
    ----------
    primitive_id : int
        Id 0..P-1 of the primitive to execute now.
    name : str
        Its name (``A``..``I``).
    total_cost : float
        Cost of the chosen sequence: eq. 19 plus the optional yaw-rate term at its leaf, plus its
        stage cost.
    cost_terms : CostTerms
        Weighted terms at that leaf.
    predicted_pose : numpy.ndarray, shape (3,)
        World pose (x m, y m, heading rad) predicted one period after executing the primitive.
    progress : float
        Progress of the measured pose along the path, in [0, 1], never decreasing.
    distance_to_path : float
        Distance in m from the measured position to the path (within the progress window).
    current_cost : float
        Eq. 19 at the measured pose (the quantity plotted in the paper's Fig. S3).
    current_cost_terms : CostTerms
        Its weighted terms.
    sequence : tuple of int
        The chosen primitive sequence (length = depth).
    goal_reached : bool
        Whether the measured pose has reached the end of the path.
    yaw_rate_cost : float
        The yaw-rate term at the chosen leaf (0 unless ``yaw_rate_weight`` > 0);
        ``total_cost`` = sum of ``cost_terms`` + this.
    """

    primitive_id: int
    name: str
    total_cost: float
    cost_terms: CostTerms
    predicted_pose: np.ndarray
    progress: float
    distance_to_path: float
    current_cost: float
    current_cost_terms: CostTerms
    sequence: tuple
    goal_reached: bool
    yaw_rate_cost: float = 0.0


#: Below this yaw rate [rad/s] (and ``stall_speed``) the robot counts as standing still.
STALL_YAW_RATE = 0.01


def _vector(value, name, unit):
    v = np.asarray(value, dtype=float).reshape(-1)
    if v.shape != (3,):
        raise ValueError(f"{name} has {v.size} values; expected 3 ({unit})")
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{name} {v.tolist()} is not finite; expected 3 finite values ({unit})")
    return v


class Planner:
    """Library-backed receding-horizon planner following one path.

    Parameters
    ----------
    model : frog_planner.core.transition_model.TransitionModel
    path : frog_planner.core.paths.Path
    settings : PlannerSettings
        How to decide (checked when built; ``PlannerSettings.paper()`` is the paper's exact
        cost). The fields used here:

        - ``w_distance``, ``w_heading``, ``w_progress``: eq. 19 weights (paper: 500, 50, 300;
          default 8000, 100, 300). The paper's progress term rewards cutting inside a bend (the
          projection of a point inside a curve runs ahead) and the ellipse is cut by 3 cm; with
          the distance weighed 16 times more, depth 2 and the stage cost, the in-process
          evaluator on the twin's robots (seeds 11-16, the nine paths) sums 4.6 cm of mean
          distance against the paper planner's 13.0 cm, for about 10 % more time;
        - ``depth``: search depth H, 1-5 (the paper found 1 best on hardware; default 2);
        - ``heading_lookahead``: 0 (the paper, the default) is the heading error against the path
          tangent; > 0 (m) against the direction to the path point this far ahead of the closest
          one (see :func:`path_cost`), which turned the paper's weights towards the path sooner;
        - ``velocity_lookahead``: 0 (the paper, the default) costs the predicted leaf pose; > 0 (s)
          the leaf pose extrapolated by its predicted velocities over this time (see
          :func:`search`): the frog keeps turning for seconds after a kick, which the pose one
          period ahead does not show (the stage cost at depth 2 sees it better);
        - ``yaw_rate_weight``: w_r per rad/s; 0 (the paper) leaves it out. > 0 adds w_r *
          |predicted yaw rate - path curvature * predicted forward speed| at the leaf;
        - ``stage_cost``: False (the paper) costs a sequence at its leaf; True (default) sums the
          cost at each of its period ends (depth > 1), so a good leaf reached by a detour costs
          the detour (at depth 2 without it the lines are followed twice as badly);
        - ``allow_no_action``: True (the paper) lets the search choose 'no action' (coast); False
          (default) makes every period until the goal fire limbs: with the distance weighed high,
          coasting on the path is otherwise cheapest and the frog never leaves the ellipse's start;
        - ``stall_speed``: m/s; 0 (the paper) disables. When the robot stands still (planar
          speed below this, yaw rate below 0.01 rad/s) short of the goal and the cheapest
          sequence starts with the no-action primitive, the cheapest sequence starting with an
          action is taken instead: from rest, no action leaves the state and therefore the
          decision unchanged, so the planner would wait forever.
    expander : callable, optional
        Replaces the library's predictions in the search (see :func:`search`); ``model`` then
        only names the primitives.

    Examples
    --------
    >>> planner = Planner(TransitionModel.load("library.npz", period=1.5), ellipse_path())  # doctest: +SKIP
    >>> decision = planner.decide(pose=[0, 0, 0], body_velocity=[0.02, 0, 0])             # doctest: +SKIP
    >>> decision.primitive_id, decision.name                                                  # doctest: +SKIP
    (1, 'B')
    """

    def __init__(self, model, path, settings: PlannerSettings = PlannerSettings(), expander=None):
        if not isinstance(settings, PlannerSettings):
            raise TypeError(f"settings is a {type(settings).__name__}; expected PlannerSettings")
        self.model = model
        self.path = path
        self.settings = settings
        self.weights = settings.weights
        self.depth = settings.depth
        self.heading_lookahead = settings.heading_lookahead
        self.velocity_lookahead = settings.velocity_lookahead
        self.yaw_rate_weight = settings.yaw_rate_weight
        self.stall_speed = settings.stall_speed
        self.allow_no_action = settings.allow_no_action
        self.stage_cost = settings.stage_cost
        self.expander = expander
        bits = getattr(model, "primitive_bits", None)
        idle = [i for i, b in enumerate(bits or []) if set(b) <= {"0"}]
        self._idle = idle[0] if idle else None
        self._progress = 0.0
        self._previous_pose = None

    @property
    def progress(self):
        """Current progress in [0, 1] (monotone)."""
        return self._progress

    def reset(self, progress=0.0):
        """Start over (new run) from ``progress`` in [0, 1]."""
        if not 0.0 <= progress <= 1.0:
            raise ValueError(f"progress {progress} must be in [0, 1]")
        self._progress = float(progress)
        self._previous_pose = None

    def rank_first_actions(self, pose, body_velocity, depth=2):
        """First primitives, best first, by the cheapest leaf each leads to under the library's predictions.

        The beam of the simulator-in-the-loop mode: only the best few first primitives are
        rolled out to depth 2. The planner's state (progress) is not changed.
        """
        pose = _vector(pose, "pose", "x m, y m, heading rad")
        body_velocity = _vector(body_velocity, "body velocity", "forward m/s, lateral m/s, yaw rate rad/s")
        now = path_cost(self.path, pose, self.weights, self._progress, self.heading_lookahead)
        progress = max(self._progress, float(now.progress[0]))
        result = search(self.model, self.path, pose, body_velocity, depth, self.weights, progress,
                        self.heading_lookahead, self.velocity_lookahead, self.yaw_rate_weight,
                        stage_cost=self.stage_cost)
        per_first = result.leaf_total.reshape(self.model.n_primitives, -1).min(axis=1)
        if not self.allow_no_action and self._idle is not None:
            per_first[self._idle] = np.inf
        return [int(i) for i in np.argsort(per_first, kind="stable")]

    def decide(self, pose, body_velocity, expander=None):
        """Choose the primitive to execute now (Algorithm 1).

        Parameters
        ----------
        pose : array_like, shape (3,)
            Measured world pose: x m, y m, heading rad.
        body_velocity : array_like, shape (3,)
            Measured body velocity: forward m/s, lateral m/s, yaw rate rad/s
            (nav_msgs/Odometry twist, which is in the child (body) frame).
        expander : callable, optional
            For this decision only, instead of the planner's own (see :func:`search`): e.g.
            the simulator's rollouts from this pose.

        Returns
        -------
        Decision

        Raises
        ------
        ValueError
            If pose or velocity are not 3 finite values (the planner state is unchanged).
        """
        pose = _vector(pose, "pose", "x m, y m, heading rad")
        body_velocity = _vector(body_velocity, "body velocity", "forward m/s, lateral m/s, yaw rate rad/s")
        now = path_cost(self.path, pose, self.weights, self._progress, self.heading_lookahead)
        self._progress = max(self._progress, float(now.progress[0]))
        result = search(self.model, self.path, pose, body_velocity, self.depth, self.weights, self._progress,
                        self.heading_lookahead, self.velocity_lookahead, self.yaw_rate_weight,
                        expander or self.expander, stage_cost=self.stage_cost)
        goal = self.path.goal_reached(pose, self._progress, self._previous_pose)
        self._previous_pose = pose[:2].copy()
        best = result.best_leaf
        n_prim = len(result.first_poses)
        span = n_prim ** (self.depth - 1)             # leaves per first action (base-P digits)
        standing = (np.hypot(body_velocity[0], body_velocity[1]) < self.stall_speed
                    and abs(body_velocity[2]) < STALL_YAW_RATE)
        if (standing or not self.allow_no_action) and not goal and self._idle is not None \
                and best // span == self._idle:
            totals = result.leaf_total.copy()
            totals[self._idle * span:(self._idle + 1) * span] = np.inf
            if np.isfinite(totals.min()):       # a beam may have predicted no other first action
                best = int(np.argmin(totals))
        first = best // span
        sequence = tuple(int(best // n_prim ** (self.depth - 1 - d)) % n_prim for d in range(self.depth))
        return Decision(
            primitive_id=int(first), name=self.model.primitive_names[first],
            total_cost=float(result.leaf_total[best]),
            cost_terms=CostTerms.from_array(result.leaf_cost.terms[best]),
            predicted_pose=result.first_poses[first].copy(), progress=self._progress,
            distance_to_path=float(now.distance[0]), current_cost=float(now.total[0]),
            current_cost_terms=CostTerms.from_array(now.terms[0]), sequence=sequence,
            goal_reached=goal,
            yaw_rate_cost=float(result.yaw_rate_cost[best]))

    def decide_from_world_state(self, state):
        """:meth:`decide` from a world-frame state [x, y, theta, x_dot, y_dot, theta_dot] (Algorithm 1 step 5).

        Parameters
        ----------
        state : array_like, shape (6,)
            m, m, rad, m/s, m/s, rad/s; the planar velocity is in the world frame and is
            rotated by -theta into the body frame.
        """
        s = np.asarray(state, dtype=float).reshape(-1)
        if s.shape != (6,):
            raise ValueError(f"state has {s.size} values; expected 6 (x, y, theta, x_dot, y_dot, theta_dot)")
        body = world_to_body(s[2], s[3:5])
        return self.decide(s[:3], [body[0], body[1], s[5]])
