"""Cost (eq. 19) and exhaustive tree search over primitive sequences (Algorithm 1).

All P^H action sequences of depth H are expanded level by level as arrays: level d holds
P^d predicted states, one nearest-neighbour query per state and one eq. 18 update for all
P children at once. The cost is evaluated at the leaves (Algorithm 1 step 15) and the first
action of the cheapest leaf is returned. Leaf i encodes the sequence of its base-P digits,
most significant first, so ties go to the lexicographically smallest sequence.
"""

from dataclasses import dataclass

import numpy as np

from .prediction import apply_transition
from frog_common.se2 import twist_arc, wrap_angle

MAX_DEPTH = 5


@dataclass(frozen=True)
class CostWeights:
    """Weights of eq. 19 (paper: w_a = 500, w_b = 50, w_c = 300).

    Attributes
    ----------
    distance : float
        w_a, per m of distance to the path.
    heading : float
        w_b, per rad of heading error against the path tangent.
    progress : float
        w_c, per unit of missing progress (1 - s_c).
    """

    distance: float = 500.0
    heading: float = 50.0
    progress: float = 300.0

    def __post_init__(self):
        for name in ("distance", "heading", "progress"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0.0):
                raise ValueError(f"cost weight {name} = {value} must be a finite number >= 0")


@dataclass(frozen=True)
class PathCost:
    """Eq. 19 evaluated for M poses.

    Attributes
    ----------
    total : numpy.ndarray, shape (M,)
        C = w_a d + w_b |heading error| + w_c (1 - s_c).
    terms : numpy.ndarray, shape (M, 3)
        The three weighted terms (distance, heading, progress).
    distance : numpy.ndarray, shape (M,)
        d in m.
    heading_error : numpy.ndarray, shape (M,)
        |wrap(theta - path tangent)| in rad, in [0, pi].
    progress : numpy.ndarray, shape (M,)
        s_c in [0, 1].
    """

    total: np.ndarray
    terms: np.ndarray
    distance: np.ndarray
    heading_error: np.ndarray
    progress: np.ndarray


def path_cost(path, poses, weights, previous_progress=0.0, heading_lookahead=0.0):
    """Cost of eq. 19 for poses against a path, closest point searched ahead of ``previous_progress``.

    Parameters
    ----------
    path : frog_planner.core.paths.Path
    poses : array_like, shape (M, 3) or (3,)
        x m, y m, heading rad (world frame).
    weights : CostWeights
    previous_progress : float
        Progress in [0, 1] from which the closest point is searched (monotone progress).
    heading_lookahead : float
        0 (the paper): the heading error is measured against the path tangent at the closest
        point. > 0 (m): against the direction from the pose to the path point this far
        further along (clipped at the end), which rewards turning back towards the path.

    Returns
    -------
    PathCost
    """
    p = np.atleast_2d(np.asarray(poses, dtype=float))
    proj = path.project(p[:, :2], previous_progress)
    reference = proj.tangent_heading
    if heading_lookahead > 0.0:
        target = path.point_at(np.minimum(proj.progress + heading_lookahead / path.length, 1.0))
        to_target = target - p[:, :2]
        # At the target itself (only possible at the end) there is no direction: keep the tangent.
        reference = np.where(np.hypot(to_target[:, 0], to_target[:, 1]) > 1e-9,
                             np.arctan2(to_target[:, 1], to_target[:, 0]), reference)
    elif heading_lookahead < 0.0 or not np.isfinite(heading_lookahead):
        raise ValueError(f"heading_lookahead {heading_lookahead} m must be a finite number >= 0")
    heading_error = np.abs(wrap_angle(p[:, 2] - reference))
    terms = np.column_stack([weights.distance * proj.distance, weights.heading * heading_error,
                             weights.progress * (1.0 - proj.progress)])
    return PathCost(total=terms.sum(axis=1), terms=terms, distance=proj.distance,
                    heading_error=heading_error, progress=proj.progress)


@dataclass(frozen=True)
class SearchResult:
    """Outcome of a tree search.

    Attributes
    ----------
    sequence : tuple of int
        Primitive ids of the cheapest sequence, first action first (length H).
    leaf_cost : PathCost
        Eq. 19 at every leaf (P^H entries, leaf i = base-P digits of i).
    leaf_poses : numpy.ndarray, shape (P^H, 3)
        Predicted world poses after H periods.
    first_poses : numpy.ndarray, shape (P, 3)
        Predicted world pose after one period for each first action.
    best_leaf : int
        Index of the cheapest leaf.
    yaw_rate_cost : numpy.ndarray, shape (P^H,)
        w_r * |yaw rate - path curvature * forward speed| at every leaf (zeros when w_r = 0).
    stage_cost : numpy.ndarray, shape (P^H,)
        With ``stage_cost``: the cost (eq. 19 plus the yaw-rate term) at the period ends before
        each leaf, summed; zeros otherwise.
    """

    sequence: tuple
    leaf_cost: PathCost
    leaf_poses: np.ndarray
    first_poses: np.ndarray
    best_leaf: int
    yaw_rate_cost: np.ndarray
    stage_cost: np.ndarray = None

    @property
    def leaf_total(self):
        """Cost of every sequence: eq. 19 plus the yaw-rate term at its leaf, plus its stage cost,
        shape (P^H,); inf where not predicted."""
        total = self.leaf_cost.total + self.yaw_rate_cost
        if self.stage_cost is not None:
            total = total + self.stage_cost
        return np.where(np.isfinite(total), total, np.inf)

    @property
    def first_action(self):
        """Primitive id to execute now (Algorithm 1 steps 16-17)."""
        return self.sequence[0]

    @property
    def total_cost(self):
        """Cost of the cheapest sequence (:attr:`leaf_total` of the best leaf)."""
        return float(self.leaf_total[self.best_leaf])


def expand_tree(model, pose, body_velocity, depth, return_velocities=False, return_levels=False):
    """Predict the leaves of all P^H sequences (Algorithm 1 steps 5-14, vectorised).

    Parameters
    ----------
    model : frog_planner.core.transition_model.TransitionModel
    pose : array_like, shape (3,)
        Current world pose (x m, y m, heading rad).
    body_velocity : array_like, shape (3,)
        Current body velocity (forward m/s, lateral m/s, yaw rate rad/s).
    depth : int
        H, 1 <= H <= 5.
    return_velocities : bool
        Also return the predicted body velocities at the leaves.
    return_levels : bool
        Also return every level (with ``return_velocities``).

    Returns
    -------
    leaf_poses : numpy.ndarray, shape (P^H, 3)
    first_poses : numpy.ndarray, shape (P, 3)
    leaf_velocities : numpy.ndarray, shape (P^H, 3)
        Only with ``return_velocities``: forward m/s, lateral m/s, yaw rate rad/s.
    levels : list of (poses, velocities)
        Only with ``return_levels``: level d (0-based) holds the P^(d+1) period ends of d + 1
        periods, in base-P order.
    """
    depth = int(depth)
    if not 1 <= depth <= MAX_DEPTH:
        raise ValueError(f"search depth {depth} is out of range; expected 1-{MAX_DEPTH}")
    poses, first, velocities, levels = _chain(pose, body_velocity, depth, lambda level, vel: model.lookup(vel))
    if return_levels:
        return poses, first, velocities, levels
    if return_velocities:
        return poses, first, velocities
    return poses, first


def _chain(pose, body_velocity, depth, transitions):
    """Leaves, first poses, leaf velocities and every level (poses, velocities) of a tree;
    ``transitions(level, velocities)`` -> (M, P, 6)."""
    poses = np.asarray(pose, dtype=float).reshape(1, 3)
    velocities = np.asarray(body_velocity, dtype=float).reshape(1, 3)
    levels = []
    for level in range(depth):
        trans = transitions(level, velocities)                         # (M, P, 6)
        poses, velocities = apply_transition(poses[:, None, :], trans)  # (M, P, 3) each, eq. 18
        poses = poses.reshape(-1, 3)
        velocities = velocities.reshape(-1, 3)
        levels.append((poses, velocities))
    return poses, levels[0][0].copy(), velocities, levels


def check_rows(rows, depth, n_primitives) -> list:
    """The level sizes P, P^2, ... of a depth-``depth`` tree; raises ValueError if ``rows`` is not
    its (P + ... + P^H, 6) array (see :func:`tree_from_rows`)."""
    sizes = [int(n_primitives) ** (d + 1) for d in range(int(depth))]
    shape = np.shape(rows)
    if shape != (sum(sizes), 6):
        raise ValueError(f"rows have shape {shape}; a depth-{depth} tree of {n_primitives} primitives needs "
                         f"({sum(sizes)}, 6)")
    return sizes


def tree_from_rows(pose, rows, depth, n_primitives):
    """The tree of :func:`expand_tree` from given transitions instead of the library's.

    Parameters
    ----------
    pose : array_like, shape (3,)
        World pose the rows start from.
    rows : array_like, shape (P + P^2 + ... + P^H, 6)
        Level by level, parents in base-P order (each parent's P children): dx, dy, dyaw in
        the body frame at the period's start, u, v, w at its end (the layout of the
        simulator's ``frog/rollouts`` service and of the motion library). NaN rows (branches
        not simulated) give NaN leaves, which :func:`search` never chooses.
    depth : int
    n_primitives : int

    Returns
    -------
    leaf_poses, first_poses, leaf_velocities, levels
        As :func:`expand_tree` with ``return_levels``.
    """
    depth, p = int(depth), int(n_primitives)
    rows = np.asarray(rows, dtype=float)
    sizes = check_rows(rows, depth, p)
    offsets = np.cumsum([0] + sizes)
    return _chain(pose, np.zeros(3), depth,
                  lambda level, vel: rows[offsets[level]:offsets[level + 1]].reshape(-1, p, 6))


def reanchor_rows(rows, lead_transition, n_primitives):
    """Rows whose level 1 spans a lead and a period, made to start where the lead ended.

    ``rows`` (the layout of :func:`tree_from_rows`) were rolled out from a pose observed before
    the decision is executed; ``lead_transition`` (dx, dy, dyaw in that pose's frame, and the
    twist then) is where the coast to the execution ended. Level 1 then becomes each first
    period seen from that end, so the tree can be chained from the pose tracked at the
    execution instead of the lead's prediction of it; deeper levels are relative to their
    parents already and stay.
    """
    rows = np.array(rows, dtype=float)
    lead = np.asarray(lead_transition, dtype=float).reshape(-1)
    if lead.shape != (6,) or not np.all(np.isfinite(lead)):
        raise ValueError(f"lead transition {lead.tolist()} must be 6 finite values (dx, dy, dyaw, u, v, w)")
    first = rows[:int(n_primitives)]
    c, s = np.cos(lead[2]), np.sin(lead[2])
    dx, dy = first[:, 0] - lead[0], first[:, 1] - lead[1]
    first[:, 0], first[:, 1] = c * dx + s * dy, -s * dx + c * dy
    first[:, 2] = first[:, 2] - lead[2]
    return rows


def extrapolate_poses(poses, body_velocities, horizon):
    """Poses after coasting ``horizon`` seconds at constant body velocity and yaw rate.

    Exact integration of a constant twist (a circular arc): the body turns by r*tau while
    moving with (u, v) in its own frame. Used to make the velocity state a leaf ends in
    visible to the cost (a turn's payoff is the yaw rate that keeps acting after T).

    Parameters
    ----------
    poses : array_like, shape (M, 3)
        x m, y m, heading rad (world frame).
    body_velocities : array_like, shape (M, 3)
        forward m/s, lateral m/s, yaw rate rad/s.
    horizon : float
        tau in s, >= 0 (0 returns the poses unchanged).

    Returns
    -------
    numpy.ndarray, shape (M, 3)
        Heading wrapped to [-pi, pi).
    """
    p = np.atleast_2d(np.asarray(poses, dtype=float))
    if float(horizon) == 0.0:
        return p.copy()
    out = twist_arc(p, np.atleast_2d(np.asarray(body_velocities, dtype=float)), float(horizon))
    out[:, 2] = wrap_angle(out[:, 2])
    return out


def search(model, path, pose, body_velocity, depth=1, weights=CostWeights(), previous_progress=0.0,
           heading_lookahead=0.0, velocity_lookahead=0.0, yaw_rate_weight=0.0, expander=None, stage_cost=False):
    """Cheapest of all P^H primitive sequences under eq. 19 (Algorithm 1).

    Parameters
    ----------
    model : frog_planner.core.transition_model.TransitionModel
    path : frog_planner.core.paths.Path
    pose : array_like, shape (3,)
        Current world pose (x m, y m, heading rad).
    body_velocity : array_like, shape (3,)
        Current body velocity (forward m/s, lateral m/s, yaw rate rad/s).
    depth : int
        H, 1 <= H <= 5.
    weights : CostWeights
    previous_progress : float
        The current progress in [0, 1]; leaves' progress is searched ahead of it.
    heading_lookahead : float
        See :func:`path_cost` (0: the paper's tangent heading error).
    velocity_lookahead : float
        0 (the paper): eq. 19 at the leaf poses. > 0 (s): at the leaf poses extrapolated by
        their predicted body velocities and yaw rate over this time (:func:`extrapolate_poses`),
        so that the velocity state a sequence leaves behind counts.
    yaw_rate_weight : float
        w_r per rad/s (0: the paper). Adds w_r * |r - kappa * u| at each leaf: the predicted
        yaw rate r against the rate the path needs at the predicted forward speed u
        (kappa: signed path curvature at the leaf's closest point), so that a turn's payoff,
        the yaw rate it leaves, counts although its heading change within T is small.
    expander : callable, optional
        ``expander(pose, body_velocity, depth) -> (leaf_poses, first_poses, leaf_velocities[, levels])``
        with the leaves in the order of :func:`expand_tree`; replaces the library prediction
        (e.g. by the simulator itself, to separate the library's error from the planner's).
    stage_cost : bool
        False (the paper): a sequence costs its leaf. True: the sum of the cost at each of its
        period ends, so that a sequence cannot buy a good leaf with a detour on the way (the
        expander must then give the levels).

    Returns
    -------
    SearchResult
        ``leaf_poses`` are the predicted (not extrapolated) leaves.
    """
    if not (np.isfinite(velocity_lookahead) and velocity_lookahead >= 0.0):
        raise ValueError(f"velocity_lookahead {velocity_lookahead} s must be a finite number >= 0")
    if not (np.isfinite(yaw_rate_weight) and yaw_rate_weight >= 0.0):
        raise ValueError(f"yaw_rate_weight {yaw_rate_weight} must be a finite number >= 0")
    tree = (expand_tree(model, pose, body_velocity, depth, return_levels=True) if expander is None
            else expander(pose, body_velocity, depth))
    leaves, first, leaf_velocities = tree[:3]

    def costs(poses, velocities):
        costed = extrapolate_poses(poses, velocities, velocity_lookahead) if velocity_lookahead > 0 else poses
        c = path_cost(path, costed, weights, previous_progress, heading_lookahead)
        if yaw_rate_weight > 0.0:
            needed = path.curvature_at(c.progress) * velocities[:, 0]
            return c, yaw_rate_weight * np.abs(velocities[:, 2] - needed)
        return c, np.zeros(len(poses))

    cost, yaw_cost = costs(leaves, leaf_velocities)
    before = np.zeros(len(leaves))
    if stage_cost and int(depth) > 1:
        if len(tree) < 4:
            raise ValueError("stage_cost needs every level of the tree; this expander gives only its leaves")
        for level_poses, level_velocities in tree[3][:-1]:      # the leaves' own cost is in ``cost``
            c, y = costs(level_poses, level_velocities)
            before = before + np.repeat(c.total + y, len(leaves) // len(level_poses))
    # leaves an expander did not predict (NaN: a branch outside a beam) are never chosen
    total = cost.total + yaw_cost + before
    total = np.where(np.isfinite(total), total, np.inf)
    if not np.any(np.isfinite(total)):
        raise ValueError("no leaf of the search tree has a finite cost (every prediction is NaN)")
    best = int(np.argmin(total))
    n_prim = model.n_primitives
    digits = []
    rest = best
    for _ in range(int(depth)):
        digits.append(rest % n_prim)
        rest //= n_prim
    return SearchResult(sequence=tuple(reversed(digits)), leaf_cost=cost, leaf_poses=leaves,
                        first_poses=first, best_leaf=best, yaw_rate_cost=yaw_cost, stage_cost=before)
