"""Can this frog follow this path? Its steady turning circles against the path's curvature.

A turning primitive repeated every period settles into a circle (the yaw rate builds up
over several periods, then the centre of mass circles). The tightest of those circles, on
each side, bounds the curvature the frog can hold; where the path bends tighter, any
planner must cut the corner. Three numbers answer "is the path feasible, and what is the
best one could hope for":

- :func:`steady_turns`: each primitive's steady circle, from the transition model itself
  (library or simulator: whatever the planner predicts with);
- :func:`tight_stretches`: where along the path its radius of curvature is below the
  frog's tightest turn on that side;
- :func:`turning_limited_floor`: the smallest mean distance to the path of any curve from
  the path's start to its end whose curvature stays within the frog's limits (the "best
  cut"); with no turning at all it is the straight cut from start to end.

The floor measures the trajectory as the twin's metrics do (mean distance of samples to the
path polyline, :mod:`frog_twin.core.metrics`), sampled evenly along the curve, i.e. at
constant speed. Transient turns tighter than the steady circle (a kick from rest) are not
in it, so it is a floor for holding a turn, not for stop-and-turn manoeuvres.
"""

from __future__ import annotations

import math

from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize
from scipy.spatial import cKDTree

from .prediction import apply_transition

STEADY_PERIODS = 40          # periods simulated through the model from rest
SETTLE_PERIODS = 20          # of which the first are the build-up, not fitted
STRAIGHT_YAW = 1e-3          # rad per period: below this a primitive goes straight (radius inf)


@dataclass(frozen=True)
class SteadyTurn:
    """The circle a primitive settles into when repeated every period (centre of mass)."""

    primitive: str
    radius_m: float              # inf for a straight swim
    yaw_per_period_rad: float    # signed, + turning left (REP-103)
    speed_m_per_s: float         # along the circle
    acts: bool = True            # fires a limb (False: 'no action', which only coasts)

    @property
    def side(self) -> int:
        """+1 left, -1 right, 0 straight."""
        return 0 if not np.isfinite(self.radius_m) else int(np.sign(self.yaw_per_period_rad))


@dataclass(frozen=True)
class TurningLimits:
    """The frog's tightest steady turns on each side, and every primitive's circle."""

    left_m: float
    right_m: float
    turns: tuple

    def radius(self, side: int) -> float:
        """Tightest radius [m] when turning to ``side`` (+1 left, -1 right)."""
        return self.left_m if side > 0 else self.right_m

    def describe(self) -> str:
        def name(side):
            tight = [t for t in self.turns if t.side == side]
            return min(tight, key=lambda t: t.radius_m).primitive if tight else "-"
        return (f"tightest steady turn: left {self.left_m * 100:.1f} cm ({name(1)}), "
                f"right {self.right_m * 100:.1f} cm ({name(-1)})")


def _circle_radius(points) -> float:
    """Algebraic (Kasa) least-squares circle through ``points`` (K, 2): |p|^2 = 2 c.p + k."""
    a = np.column_stack([2.0 * points, np.ones(len(points))])
    sol = np.linalg.lstsq(a, (points ** 2).sum(axis=1), rcond=None)[0]
    return float(np.sqrt(max(sol[2] + sol[0] ** 2 + sol[1] ** 2, 0.0)))


def steady_turns(model, period: float, periods: int = STEADY_PERIODS, settle: int = SETTLE_PERIODS) -> tuple:
    """Each primitive repeated from rest through ``model`` (eq. 18 chained), its steady circle fitted.

    Parameters
    ----------
    model : TransitionModel
        Anything with ``lookup(body_velocities) -> (M, P, 6)`` and ``primitive_names``.
    period : float
        T [s] of one transition (for the speed).
    periods, settle : int
        Periods chained from rest, and how many of them are left out of the fit (build-up).

    Returns
    -------
    tuple of SteadyTurn
        One per primitive, in the model's order ('no action' included: it coasts to rest).
    """
    if not (periods > settle + 2 and settle >= 0):
        raise ValueError(f"periods = {periods} must exceed settle = {settle} by at least 3")
    if not (np.isfinite(period) and period > 0):
        raise ValueError(f"period = {period!r} s must be a positive number")
    n = len(model.primitive_names)
    pose = np.zeros((n, 3))
    vel = np.zeros((n, 3))
    track, yaw = [], []
    rows = np.arange(n)
    for _ in range(periods):
        trans = model.lookup(vel)[rows, rows]                 # primitive p from its own state
        pose, vel = apply_transition(pose, trans)
        track.append(pose[:, :2].copy())
        yaw.append(trans[:, 2])
    track = np.array(track)[settle:]                          # (K, P, 2)
    yaw = np.array(yaw)[settle:]
    bits = getattr(model, "primitive_bits", None) or [None] * n
    out = []
    for p, name in enumerate(model.primitive_names):
        step = np.linalg.norm(np.diff(track[:, p], axis=0), axis=1)
        dyaw = float(np.mean(yaw[:, p]))
        radius = _circle_radius(track[:, p]) if abs(dyaw) >= STRAIGHT_YAW else float("inf")
        acts = bits[p] is None or "1" in str(bits[p])
        out.append(SteadyTurn(str(name), radius, dyaw, float(step.mean() / period), acts))
    return tuple(out)


def turning_limits(turns, min_speed: float = 0.002) -> TurningLimits:
    """The tightest circles on each side among primitives that fire a limb and move (>= ``min_speed`` m/s).

    A primitive that barely moves traces a tiny "circle" that is no way to follow a path, so
    it does not count; nor does 'no action', whose drift (a library's nearest states at low
    speed: about 3 mm/s on a 5 cm "circle" in the default library) is no turn the frog can hold.
    """
    def tightest(side):
        r = [t.radius_m for t in turns if t.side == side and t.acts and t.speed_m_per_s >= min_speed]
        return min(r) if r else float("inf")
    return TurningLimits(tightest(1), tightest(-1), tuple(turns))


def tight_stretches(path, limits: TurningLimits) -> list:
    """Stretches of ``path`` tighter than the frog can turn.

    Returns
    -------
    list of dict
        ``start_m``, ``end_m`` (arc length), ``start``, ``end`` (progress 0-1), ``min_radius_m``
        (the path's tightest radius in the stretch) and ``side`` (+1 left, -1 right), in path order.
    """
    k = np.asarray(path.curvatures, dtype=float)
    s = np.asarray(path.arc_length, dtype=float)
    limit = np.where(k > 0, 1.0 / limits.left_m, 1.0 / limits.right_m)
    tight = np.abs(k) > limit
    out = []
    i = 0
    while i < len(k):
        if not tight[i]:
            i += 1
            continue
        j = i
        while j + 1 < len(k) and tight[j + 1] and np.sign(k[j + 1]) == np.sign(k[i]):
            j += 1
        kmax = float(np.max(np.abs(k[i:j + 1])))
        out.append({"start_m": float(s[i]), "end_m": float(s[j]), "start": float(s[i] / path.length),
                    "end": float(s[j] / path.length), "min_radius_m": 1.0 / kmax, "side": int(np.sign(k[i]))})
        i = j + 1
    return out


def radius_ahead(path, progress: float, lookahead: float) -> tuple:
    """The path's smallest radius of curvature [m] in ``[progress, progress + lookahead m]``, and its side."""
    s0 = float(np.clip(progress, 0.0, 1.0)) * path.length
    inside = (path.arc_length >= s0) & (path.arc_length <= s0 + lookahead)
    k = np.asarray(path.curvatures)[inside]
    if not len(k) or not np.any(k):
        return float("inf"), 0
    i = int(np.argmax(np.abs(k)))
    return float(1.0 / abs(k[i])), int(np.sign(k[i]))


def feasibility_at(path, limits: TurningLimits | None, progress: float, lookahead: float) -> tuple:
    """(turn_radius_limit, path_radius_ahead, too_tight) at ``progress``: the status's feasibility fields.

    The frog's tightest steady turn on the side the path bends within ``lookahead`` m ahead
    (either side's tighter one where it is straight), the path's tightest radius there, and
    whether the path is tighter than the frog can turn; NaN, NaN, False without ``limits``.
    """
    if limits is None:
        return math.nan, math.nan, False
    r, side = radius_ahead(path, progress, lookahead)
    if side == 0:
        return min(limits.left_m, limits.right_m), r, False
    limit = limits.radius(side)
    return limit, r, r < limit


def describe_tight(path, limits: TurningLimits) -> str:
    """One sentence: where ``path`` bends tighter than the frog can turn (it will cut there), or that it does not."""
    tight = tight_stretches(path, limits)
    if not tight:
        return f"the {path.name} path is within the frog's turning circle everywhere"
    share = sum(t["end_m"] - t["start_m"] for t in tight) / path.length
    where = ", ".join(f"{t['start']:.2f}-{t['end']:.2f} (r {t['min_radius_m'] * 100:.1f} cm)" for t in tight)
    return (f"the {path.name} path bends tighter than the frog can turn over {share * 100:.0f} % of its length, "
            f"at progress {where}: it will cut there")


def _distance_to_polyline(points, ref):
    a, d = ref[:-1], np.diff(ref, axis=0)
    p = points[:, None, :]
    t = np.clip(((p - a) * d).sum(-1) / np.maximum((d * d).sum(-1), 1e-300), 0.0, 1.0)
    return np.min(np.linalg.norm(a + t[..., None] * d - p, axis=-1), axis=1)


@dataclass(frozen=True)
class Floor:
    """The best turning-limited cut of a path, and the straight cut."""

    mean_distance_m: float       # best curve within the frog's curvature limits
    straight_cut_m: float        # straight from the path's start to its end
    points: np.ndarray           # (K, 2) the best curve [m]


def _curve(start, heading, kappa, length, per_segment):
    """Points of a curve of piecewise-constant curvature ``kappa`` (N segments of length/N)."""
    return _curve_parts(start, heading, kappa, length, per_segment)[0]


def _curve_parts(start, heading, kappa, length, per_segment):
    """The points, and what :func:`_curve_gradient` needs: step length, substep curvatures and headings."""
    ds = length / (len(kappa) * per_segment)
    k = np.repeat(kappa, per_segment)
    before = np.concatenate([[0.0], np.cumsum(k)[:-1]])            # curvature summed over earlier substeps
    # heading at each substep's midpoint (exact arcs would need a branch at k = 0; O(ds^2))
    mid = heading + ds * (before + 0.5 * k)
    xy = np.cumsum(np.column_stack([np.cos(mid), np.sin(mid)]) * ds, axis=0)
    return np.vstack([start, start + xy]), ds, k, before, mid


def _curve_gradient(parts, weights, per_segment):
    """Gradient of sum_i weights_i . p_i with respect to (heading, length, kappa) of :func:`_curve`.

    ``weights`` (M + 1, 2) is d(objective)/d(point i). Point i sums the substeps m < i, so each
    substep sees the suffix sum of the weights after it; then the chain rule through the
    midpoint headings (reverse accumulation: O(M)).
    """
    _, ds, k, before, mid = parts
    suffix = np.cumsum(weights[::-1], axis=0)[::-1][1:]          # G_m = sum_{i > m} w_i, (M, 2)
    u = np.column_stack([np.cos(mid), np.sin(mid)])
    a = ds * (suffix[:, 0] * -u[:, 1] + suffix[:, 1] * u[:, 0])  # d/d(mid_m)
    d_heading = a.sum()
    d_ds = float(np.sum(suffix * u)) + float(np.sum(a * (before + 0.5 * k)))
    later = np.concatenate([np.cumsum(a[::-1])[::-1][1:], [0.0]])  # sum_{m > l} a_m
    d_k = ds * (later + 0.5 * a)
    d_kappa = d_k.reshape(-1, per_segment).sum(axis=1)
    return d_heading, d_ds / len(k), d_kappa          # d/d(length): ds = length / M


def turning_limited_floor(path, limits: TurningLimits, segments: int = 20, per_segment: int = 5,
                          spacing: float = 5e-4) -> Floor:
    """Smallest mean distance to ``path`` of a curve from its start to its end within the turn limits.

    The curve has ``segments`` pieces of constant curvature in [-1/right, 1/left], a free
    start heading and a free length; its end must lie within the path's goal tolerance of the
    path's end (a constraint), as the run's metric stops there. Solved by SLSQP from two
    starts (the path's own curvature clipped to the limits, and the straight cut); the better
    one is kept. A local optimum, so an upper bound on the true floor that is tight in
    practice, and never above the straight cut when going straight is allowed.
    While optimising, the distance is to the nearest of the path's points ``spacing`` m apart
    (a KD-tree; off by at most spacing / 2); the result is measured on the polyline.
    """
    ref = np.asarray(path.points, dtype=float)
    tree = cKDTree(path.point_at(np.linspace(0.0, 1.0, max(int(path.length / spacing), 2) + 1)))
    start, goal = ref[0], ref[-1]
    tol = float(getattr(path, "goal_tolerance", 0.03))
    lo, hi = -1.0 / limits.right_m, 1.0 / limits.left_m
    chord = goal - start
    fine = max(per_segment, 1000 // segments)     # the result is measured on ~1000 points of the curve
    straight = _curve(start, np.arctan2(chord[1], chord[0]), np.zeros(segments), float(np.hypot(*chord)), fine)
    straight_cut = float(_distance_to_polyline(straight, ref).mean())
    scale = max(path.length, 1e-6)

    n_points = segments * per_segment + 1

    def parts(z):
        return _curve_parts(start, z[0], z[2:], z[1] * scale, per_segment)

    def points(z):
        return parts(z)[0]

    def pulled_back(z, pr, weights):     # d/dz of sum_i weights_i . p_i (length = z[1] * scale)
        dh, dlen, dk = _curve_gradient(pr, weights, per_segment)
        return np.r_[dh, dlen * scale, dk]

    def mean_distance(z):
        pr = parts(z)
        dist, idx = tree.query(pr[0])
        off = pr[0] - tree.data[idx]
        unit = off / np.maximum(dist, 1e-12)[:, None]
        return float(dist.mean()) / scale, pulled_back(z, pr, unit / (n_points * scale))

    def reach(z):                       # >= 0: the end is within the goal tolerance (squared, smooth)
        end = points(z)[-1]
        return ((tol / scale) ** 2 - float(np.sum((end - goal) ** 2)) / scale ** 2) * 1e3

    def reach_gradient(z):
        pr = parts(z)
        w = np.zeros((n_points, 2))
        w[-1] = -2e3 * (pr[0][-1] - goal) / scale ** 2
        return pulled_back(z, pr, w)

    bounds = [(-4 * np.pi, 4 * np.pi), (0.05, 2.0)] + [(lo, hi)] * segments
    s_mid = (np.arange(segments) + 0.5) / segments
    starts = [np.r_[path.tangent_heading_at(0.0), 1.0, np.clip(path.curvature_at(s_mid), lo, hi)],
              np.r_[np.arctan2(chord[1], chord[0]), max(np.hypot(*chord) / scale, 0.05), np.zeros(segments)]]
    best, best_mean = None, np.inf
    for z0 in starts:
        res = minimize(mean_distance, z0, jac=True, method="SLSQP", bounds=bounds,
                       constraints=[{"type": "ineq", "fun": reach, "jac": reach_gradient}],
                       options={"maxiter": 300, "ftol": 1e-10})
        pts = _curve(start, res.x[0], res.x[2:], res.x[1] * scale, fine)
        mean = float(_distance_to_polyline(pts, ref).mean())
        if np.hypot(*(pts[-1] - goal)) <= tol * 1.01 and mean < best_mean:
            best, best_mean = pts, mean
    if lo <= 0.0 <= hi and straight_cut <= best_mean:
        best, best_mean = straight, straight_cut
    if best is None:                    # cannot turn one way and the goal lies that way
        return Floor(float("nan"), straight_cut, np.empty((0, 2)))
    mean, pts = best_mean, best
    return Floor(mean, straight_cut, pts)
