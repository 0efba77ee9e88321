"""Vectorised tree search against a brute-force itertools reference on a tiny library; the planner API."""

import itertools
import math

import numpy as np
import pytest

from frog_planner.core.paths import ellipse_path, line_path, sinusoid_path
from frog_planner.core.planner import Planner
from frog_planner.core.settings import PlannerSettings
from frog_planner.core.transition_model import TransitionModel
from frog_planner.core.tree_search import CostWeights, search

W_A, W_B, W_C = 500.0, 50.0, 300.0   # paper eq. 19 weights


# ---- brute-force reference: explicit loops, math module, no frog_planner code ----------------------------------

def ref_nearest(states, q, metric, scale, k, floor_fraction=0.05):
    scored = []
    for i, s in enumerate(states):
        total = 0.0
        for c in range(3):
            denom = scale[c] if metric == "euclidean" else max(abs(q[c]), floor_fraction * scale[c])
            total += ((q[c] - s[c]) / denom) ** 2
        scored.append((math.sqrt(total), i))
    scored.sort()
    return [i for _, i in scored[:k]]


def ref_transition(table, action, neighbours):
    rows = [table[action][n] for n in neighbours]
    out = [sum(r[c] for r in rows) / len(rows) for c in range(6)]
    out[2] = math.atan2(sum(math.sin(r[2]) for r in rows), sum(math.cos(r[2]) for r in rows))
    return out


def ref_step(pose, t):
    """Eq. 18 by hand."""
    x, y, th = pose
    c, s = math.cos(th), math.sin(th)
    return (x + c * t[0] - s * t[1], y + s * t[0] + c * t[1], th + t[2]), (t[3], t[4], t[5])


def ref_cost(path, pose, prev_progress, lookahead=0.0):
    """Eq. 19: closest point on the path between s_prev and s_prev + window, by looping over segments."""
    pts, arc, L = path.points, path.arc_length, path.length
    s0 = prev_progress * L
    s1 = min(s0 + path.progress_window, L)
    best = (math.inf, None)
    for i in range(len(pts) - 1):
        lo, hi = max(arc[i], s0), min(arc[i + 1], s1)
        if lo > hi:
            continue
        seg = arc[i + 1] - arc[i]
        a = pts[i] + (lo - arc[i]) / seg * (pts[i + 1] - pts[i])
        b = pts[i] + (hi - arc[i]) / seg * (pts[i + 1] - pts[i])
        dx, dy = b[0] - a[0], b[1] - a[1]
        den = dx * dx + dy * dy
        t = 0.0 if den == 0 else min(1.0, max(0.0, ((pose[0] - a[0]) * dx + (pose[1] - a[1]) * dy) / den))
        d = math.hypot(pose[0] - a[0] - t * dx, pose[1] - a[1] - t * dy)
        if d < best[0]:
            best = (d, lo + t * (hi - lo))
    d, s = best
    tangent = np.interp(s, arc, np.unwrap(path.tangent_headings))
    if lookahead > 0.0:
        s_ahead = min(s + lookahead, L)
        tx, ty = np.interp(s_ahead, arc, pts[:, 0]), np.interp(s_ahead, arc, pts[:, 1])
        tangent = math.atan2(ty - pose[1], tx - pose[0])
    err = abs((pose[2] - tangent + math.pi) % (2 * math.pi) - math.pi)
    return W_A * d + W_B * err + W_C * (1.0 - s / L)


def ref_search(states, table, path, pose, vel, depth, metric, k, scale, prev_progress, lookahead=0.0):
    best_cost, best_seq, leaves = math.inf, None, {}
    for seq in itertools.product(range(len(table)), repeat=depth):
        p, v = pose, vel
        for a in seq:
            p, v = ref_step(p, ref_transition(table, a, ref_nearest(states, v, metric, scale, k)))
        leaves[seq] = p
        cost = ref_cost(path, p, prev_progress, lookahead)
        if cost < best_cost:
            best_cost, best_seq = cost, seq
    return best_seq, best_cost, leaves


# ---- tests ----------------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def tiny(synthetic):
    """15 initial states x 9 primitives of the kinematic test model, T = 1.5 s."""
    arrays = synthetic.library_arrays(n_states=15, horizon=1.5, sample_interval=0.25, seed=4)
    return arrays["initial_states"], arrays["transitions"][:, :, -1, :].astype(float)


@pytest.mark.parametrize("depth, metric, k", [(1, "euclidean", 1), (2, "euclidean", 1), (3, "euclidean", 1),
                                              (2, "relative", 1), (3, "relative", 1), (2, "euclidean", 2),
                                              (2, "relative", 3),
                                              pytest.param(4, "euclidean", 1, marks=pytest.mark.slow)])
def test_search_matches_brute_force(tiny, depth, metric, k):
    states, table = tiny
    model = TransitionModel(states, table, list("ABCDEFGHI"), metric=metric, k=k)
    scale = [float(np.ptp(states[:, c])) for c in range(3)]
    path = sinusoid_path(length=0.36, A=8.5, f=10.0, start=(0.0, 0.0), heading=0.1)
    for pose, vel, prev in [((0.02, 0.01, 0.2), (0.02, 0.005, 0.1), 0.05),
                            ((0.10, -0.03, -0.4), (0.035, -0.02, -0.3), 0.25)]:
        result = search(model, path, pose, vel, depth, CostWeights(), prev)
        want_seq, want_cost, leaves = ref_search(states, table, path, pose, vel, depth, metric, k, scale, prev)
        assert result.sequence == want_seq
        assert result.first_action == want_seq[0]
        assert result.total_cost == pytest.approx(want_cost, rel=1e-9)
        want = np.array([leaves[seq] for seq in itertools.product(range(9), repeat=depth)])  # leaf i = digits of i
        np.testing.assert_allclose(result.leaf_poses[:, :2], want[:, :2], atol=1e-12)
        np.testing.assert_allclose(np.cos(result.leaf_poses[:, 2] - want[:, 2]), 1.0, atol=1e-12)


@pytest.mark.parametrize("depth", [1, 2])
def test_search_with_heading_lookahead_matches_brute_force(tiny, depth):
    states, table = tiny
    model = TransitionModel(states, table, list("ABCDEFGHI"))
    scale = [float(np.ptp(states[:, c])) for c in range(3)]
    path = sinusoid_path()
    pose, vel, prev = (0.03, 0.03, 0.1), (0.03, 0.0, 0.0), 0.05
    result = search(model, path, pose, vel, depth, CostWeights(), prev, heading_lookahead=0.08)
    want_seq, want_cost, _ = ref_search(states, table, path, pose, vel, depth, "euclidean", 1, scale, prev, 0.08)
    assert result.sequence == want_seq
    assert result.total_cost == pytest.approx(want_cost, rel=1e-9)


def test_heading_lookahead_by_hand():
    from frog_planner.core.tree_search import path_cost
    path = line_path(length=0.4)
    # 5 cm left of the line at x = 0.1, facing +x: the point 0.1 m ahead is (0.2, 0).
    cost = path_cost(path, [0.1, 0.05, 0.0], CostWeights(), 0.0, heading_lookahead=0.1)
    assert cost.heading_error[0] == pytest.approx(math.atan2(0.05, 0.1))
    assert cost.total[0] == pytest.approx(W_A * 0.05 + W_B * math.atan2(0.05, 0.1) + W_C * 0.75)
    # Near the end the look-ahead point is clipped to the last point (0.4, 0).
    cost = path_cost(path, [0.38, -0.02, 0.0], CostWeights(), 0.5, heading_lookahead=0.1)
    assert cost.heading_error[0] == pytest.approx(math.atan2(0.02, 0.02))
    with pytest.raises(ValueError, match="heading_lookahead=-0.1 is below its minimum 0.0"):
        PlannerSettings(heading_lookahead=-0.1)


def test_depth_one_is_the_cheapest_single_primitive(tiny):
    states, table = tiny
    model = TransitionModel(states, table, list("ABCDEFGHI"))
    path = line_path(length=0.4)
    pose, vel = (0.0, 0.02, -0.2), (0.02, 0.0, 0.0)
    n = ref_nearest(states, vel, "euclidean", [float(np.ptp(states[:, c])) for c in range(3)], 1)
    costs = [ref_cost(path, ref_step(pose, table[a][n[0]])[0], 0.0) for a in range(9)]
    result = search(model, path, pose, vel, 1)
    assert result.first_action == int(np.argmin(costs))
    np.testing.assert_allclose(result.leaf_cost.total, costs, rtol=1e-9)


def test_weights_change_the_choice(tiny):
    states, table = tiny
    model = TransitionModel(states, table, list("ABCDEFGHI"))
    path = line_path(length=0.4)
    pose, vel = (0.0, 0.0, 0.0), (0.02, 0.0, 0.0)
    # Only progress counts: the fastest forward primitive (B drives to 4 cm/s).
    assert search(model, path, pose, vel, 1, CostWeights(0.0, 0.0, 300.0)).first_action == 1
    # Only heading counts: the primitive whose heading change from the nearest state is smallest.
    n = ref_nearest(states, vel, "euclidean", [float(np.ptp(states[:, c])) for c in range(3)], 1)[0]
    want = int(np.argmin([abs(table[a][n][2]) for a in range(9)]))
    assert search(model, path, pose, vel, 1, CostWeights(0.0, 50.0, 0.0)).first_action == want


def test_bad_depth_and_weights_are_rejected(tiny):
    states, table = tiny
    model = TransitionModel(states, table, list("ABCDEFGHI"))
    with pytest.raises(ValueError, match="depth=6 is above its maximum 5"):
        PlannerSettings(depth=6)
    with pytest.raises(ValueError, match="search depth 6 is out of range; expected 1-5"):
        search(model, line_path(), [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], 6)
    with pytest.raises(ValueError, match="cost weight distance = -1"):
        CostWeights(distance=-1.0)


def test_planner_decision_fields(tiny):
    states, table = tiny
    model = TransitionModel(states, table, list("ABCDEFGHI"))
    path = line_path(length=0.4)
    planner = Planner(model, path, PlannerSettings.paper(depth=2))
    d = planner.decide([0.1, 0.01, 0.0], [0.02, 0.0, 0.0])
    assert 0 <= d.primitive_id < 9 and d.name == "ABCDEFGHI"[d.primitive_id]
    assert len(d.sequence) == 2 and d.sequence[0] == d.primitive_id
    assert d.progress == pytest.approx(0.25)
    assert d.distance_to_path == pytest.approx(0.01)
    assert d.current_cost == pytest.approx(W_A * 0.01 + W_C * 0.75)
    assert d.current_cost_terms.distance == pytest.approx(5.0)
    assert d.current_cost_terms.heading == pytest.approx(0.0)
    assert d.total_cost == pytest.approx(d.cost_terms.distance + d.cost_terms.heading + d.cost_terms.progress)
    n = ref_nearest(states, (0.02, 0.0, 0.0), "euclidean", [float(np.ptp(states[:, c])) for c in range(3)], 1)
    np.testing.assert_allclose(d.predicted_pose[:2], ref_step((0.1, 0.01, 0.0), table[d.primitive_id][n[0]])[0][:2])
    assert not d.goal_reached
    assert planner.decide([0.395, 0.0, 0.0], [0.02, 0.0, 0.0]).goal_reached
    # With a heading look-ahead the planner measures heading against the path point 0.1 m ahead:
    # from (0.1, 0.01) that is (0.2, 0), atan(0.01 / 0.1) to the right of the heading.
    ahead = PlannerSettings(depth=2, heading_lookahead=0.1, w_heading=W_B)
    d = Planner(model, path, ahead).decide([0.1, 0.01, 0.0], [0.02, 0.0, 0.0])
    assert d.current_cost_terms.heading == pytest.approx(W_B * math.atan(0.01 / 0.1))


def test_planner_progress_is_monotone_on_the_ellipse(tiny):
    states, table = tiny
    planner = Planner(TransitionModel(states, table, list("ABCDEFGHI")), ellipse_path(), PlannerSettings(depth=1))
    path = planner.path
    rng = np.random.default_rng(2)
    history = []
    for s in np.concatenate([np.linspace(0.0, 0.6, 30), np.linspace(0.6, 0.55, 4), np.linspace(0.55, 1.0, 25)]):
        xy = path.point_at(s) + rng.normal(0.0, 0.004, 2)
        d = planner.decide([xy[0], xy[1], float(path.tangent_heading_at(s))], [0.02, 0.0, 0.0])
        history.append(d.progress)
    assert history[0] < 0.02                      # the nearby end of the ellipse is not mistaken for the start
    assert np.all(np.diff(history) >= 0.0)
    assert history[-1] > 0.97 and d.goal_reached


def test_planner_rejects_bad_measurements_and_keeps_its_state(tiny):
    states, table = tiny
    planner = Planner(TransitionModel(states, table, list("ABCDEFGHI")), line_path(length=0.4))
    planner.decide([0.2, 0.0, 0.0], [0.02, 0.0, 0.0])
    before = planner.progress
    with pytest.raises(ValueError, match=r"pose \[0.3, nan, 0.0\] is not finite"):
        planner.decide([0.3, float("nan"), 0.0], [0.02, 0.0, 0.0])
    with pytest.raises(ValueError, match="body velocity has 2 values; expected 3"):
        planner.decide([0.3, 0.0, 0.0], [0.02, 0.0])
    assert planner.progress == before
    planner.reset()
    assert planner.progress == 0.0


def test_world_state_entry_applies_step5(tiny):
    states, table = tiny
    model = TransitionModel(states, table, list("ABCDEFGHI"))
    a = Planner(model, line_path(), PlannerSettings(depth=2))
    b = Planner(model, line_path(), PlannerSettings(depth=2))
    th = 0.4
    # Body velocity (0.02 forward, 0.005 left) seen in the world frame at heading th, by hand.
    world = (0.02 * math.cos(th) - 0.005 * math.sin(th), 0.02 * math.sin(th) + 0.005 * math.cos(th))
    da = a.decide_from_world_state([0.05, 0.01, th, world[0], world[1], 0.1])
    db = b.decide([0.05, 0.01, th], [0.02, 0.005, 0.1])
    assert da.sequence == db.sequence and da.total_cost == pytest.approx(db.total_cost)


# ---- velocity look-ahead and yaw-rate term (options beyond the paper) ------------------------------------------

def ref_coast(pose, body_velocity, tau, steps=20000):
    """Constant body twist integrated by small explicit steps (independent of the closed form)."""
    x, y, th = pose
    u, v, r = body_velocity
    dt = tau / steps
    for _ in range(steps):
        mid = th + 0.5 * r * dt
        x += (math.cos(mid) * u - math.sin(mid) * v) * dt
        y += (math.sin(mid) * u + math.cos(mid) * v) * dt
        th += r * dt
    return x, y, th


@pytest.mark.parametrize("vel", [(0.02, 0.0, 0.3), (0.01, -0.005, -0.5), (0.03, 0.002, 0.0), (0.0, 0.0, 1e-8)])
def test_extrapolate_poses_follows_the_constant_twist_arc(vel):
    from frog_planner.core.tree_search import extrapolate_poses
    pose = (0.1, -0.2, 2.5)
    got = extrapolate_poses(np.array([pose]), np.array([vel]), 2.0)[0]
    want = ref_coast(pose, vel, 2.0)
    np.testing.assert_allclose(got[:2], want[:2], atol=1e-9)
    assert abs((got[2] - want[2] + math.pi) % (2 * math.pi) - math.pi) < 1e-9
    np.testing.assert_array_equal(extrapolate_poses(np.array([pose]), np.array([vel]), 0.0)[0], pose)


def test_circle_curvature_is_one_over_its_radius():
    circle = ellipse_path()                 # the paper's ellipse: a circle of radius 0.138 m, clockwise
    inner = circle.curvature_at(np.linspace(0.05, 0.95, 19))
    np.testing.assert_allclose(inner, -1.0 / 0.138, rtol=0.01)
    assert np.allclose(line_path().curvature_at([0.0, 0.5, 1.0]), 0.0)


def test_velocity_lookahead_and_yaw_rate_term_match_brute_force(tiny):
    states, table = tiny
    model = TransitionModel(states, table, list("ABCDEFGHI"))
    path = ellipse_path()
    pose, vel, tau, w_r = (0.01, 0.02, 1.2), (0.02, 0.0, -0.1), 1.5, 40.0
    scale = [float(np.ptp(states[:, c])) for c in range(3)]
    n = ref_nearest(states, vel, "euclidean", scale, 1)[0]
    costs = []
    for a in range(9):
        leaf, leaf_vel = ref_step(pose, table[a][n])
        coast = ref_coast(leaf, leaf_vel, tau)
        eq19 = ref_cost(path, coast, 0.0, 0.1)
        # the curvature the path has at the closest point, from the circle's geometry: -1/r
        kappa = -1.0 / 0.138
        costs.append(eq19 + w_r * abs(leaf_vel[2] - kappa * leaf_vel[0]))
    result = search(model, path, pose, vel, 1, CostWeights(), 0.0, heading_lookahead=0.1,
                    velocity_lookahead=tau, yaw_rate_weight=w_r)
    np.testing.assert_allclose(result.leaf_total, costs, rtol=2e-3)
    assert result.first_action == int(np.argmin(costs))
    # the leaves reported are the predicted ones, not the extrapolated ones
    np.testing.assert_allclose(result.leaf_poses[0, :2], ref_step(pose, table[0][n])[0][:2])
    with pytest.raises(ValueError, match="velocity_lookahead"):
        search(model, path, pose, vel, 1, velocity_lookahead=-1.0)
    with pytest.raises(ValueError, match="yaw_rate_weight"):
        PlannerSettings(yaw_rate_weight=float("nan"))


def _drifting_model(bits):
    """One state at rest; every action moves 2 cm forward with its own sideways drift and
    turn, 'no action' (I) moves nothing: distance to a straight path only grows with a kick."""
    table = np.zeros((9, 1, 6))
    for p in range(8):
        side = 1.0 if p % 2 else -1.0
        table[p, 0] = [0.02, side * 0.002 * (1 + p), side * 0.02 * (1 + p), 0.0, 0.0, 0.0]
    return TransitionModel(np.zeros((1, 3)), table, list("ABCDEFGHI"), primitive_bits=list(bits))


@pytest.mark.parametrize("depth", [1, 2])
def test_planner_does_not_wait_forever_at_rest(synthetic, depth):
    """A cost that weighs only the distance to the path makes 'no action' the cheapest choice
    at rest (every kick drifts off the line). Standing still, that choice would repeat
    forever; the stall guard takes the cheapest sequence that starts with an action instead.
    Moving, or with the guard off (the paper), 'no action' stays."""
    model = _drifting_model(synthetic.BITS)
    path = line_path(length=0.3)
    weights = CostWeights(distance=500.0, heading=0.0, progress=0.0)
    rest = [0.0, 0.0, 0.0]
    kw = dict(w_distance=500.0, w_heading=0.0, w_progress=0.0, depth=depth, heading_lookahead=0.0,
              velocity_lookahead=0.0, allow_no_action=True, stage_cost=False)
    paper = Planner(model, path, PlannerSettings(stall_speed=0.0, **kw))
    assert paper.decide([0.0, 0.0, 0.0], rest).name == "I"
    d = Planner(model, path, PlannerSettings(**kw)).decide([0.0, 0.0, 0.0], rest)
    assert d.name != "I" and d.sequence[0] == d.primitive_id
    # the cheapest leaf among the sequences that start with an action (brute force over leaves)
    res = search(model, path, [0.0, 0.0, 0.0], rest, depth, weights)
    span = 9 ** (depth - 1)
    allowed = [i for i in range(9 ** depth) if i // span != 8]
    assert d.total_cost == pytest.approx(min(res.leaf_total[i] for i in allowed))
    if depth == 1:
        assert d.name == "A"                  # the smallest drift (2 mm right, 0.02 rad)
    # moving, the guard stays out of the way
    moving = Planner(model, path, PlannerSettings(**kw))
    assert moving.decide([0.0, 0.0, 0.0], [0.03, 0.0, 0.0]).name == "I"
    with pytest.raises(ValueError, match="stall_speed"):
        PlannerSettings(stall_speed=-1.0)


@pytest.mark.parametrize("depth", [1, 2])
def test_no_action_can_be_left_out_while_following(synthetic, depth):
    """allow_no_action false: moving or not, the decision is the cheapest sequence that starts with
    an action (brute force over the leaves), and the beam's ranking puts 'no action' last; at the
    goal the planner still stops (I)."""
    model = _drifting_model(synthetic.BITS)
    path = line_path(length=0.3)
    kw = dict(w_distance=500.0, w_heading=0.0, w_progress=0.0, depth=depth, heading_lookahead=0.0,
              velocity_lookahead=0.0, allow_no_action=False, stage_cost=False)
    res = search(model, path, [0.0, 0.0, 0.0], [0.03, 0.0, 0.0], depth, CostWeights(500.0, 0.0, 0.0))
    span = 9 ** (depth - 1)
    cheapest = min(res.leaf_total[i] for i in range(9 ** depth) if i // span != 8)
    planner = Planner(model, path, PlannerSettings(**kw))
    d = planner.decide([0.0, 0.0, 0.0], [0.03, 0.0, 0.0])
    assert d.name != "I" and d.total_cost == pytest.approx(cheapest)
    assert planner.rank_first_actions([0.0, 0.0, 0.0], [0.03, 0.0, 0.0], depth=depth)[-1] == 8
    end = Planner(model, path, PlannerSettings(**kw))
    assert end.decide([0.3, 0.0, 0.0], [0.0, 0.0, 0.0]).name == "I"          # goal reached


def _reference_rows(states, table, pose, vel, depth, scale):
    """Rows of the rollout service's layout, written by the brute-force reference (level by level, base P)."""
    rows, velocities = [], [vel]
    for _ in range(depth):
        nxt = []
        for v in velocities:
            for a in range(len(table)):
                t = ref_transition(table, a, ref_nearest(states, v, "euclidean", scale, 1))
                rows.append(t)
                nxt.append(tuple(t[3:]))
        velocities = nxt
    return np.array(rows)


@pytest.mark.parametrize("depth", [1, 2, 3])
def test_given_rows_chain_to_the_same_search_as_the_library(tiny, depth):
    from frog_planner.core.tree_search import tree_from_rows
    states, table = tiny
    model = TransitionModel(states, table, list("ABCDEFGHI"))
    scale = [float(np.ptp(states[:, c])) for c in range(3)]
    path = sinusoid_path(length=0.36, A=8.5, f=10.0, start=(0.0, 0.0), heading=0.1)
    pose, vel, prev = (0.10, -0.03, -0.4), (0.035, -0.02, -0.3), 0.25
    rows = _reference_rows(states, table, pose, vel, depth, scale)
    result = search(model, path, pose, vel, depth, CostWeights(), prev,
                    expander=lambda p, v, d: tree_from_rows(p, rows, d, 9))
    want_seq, want_cost, leaves = ref_search(states, table, path, pose, vel, depth, "euclidean", 1, scale, prev)
    assert result.sequence == want_seq
    assert result.total_cost == pytest.approx(want_cost, rel=1e-9)
    want = np.array([leaves[seq] for seq in itertools.product(range(9), repeat=depth)])
    np.testing.assert_allclose(result.leaf_poses[:, :2], want[:, :2], atol=1e-12)
    with pytest.raises(ValueError, match="needs"):
        tree_from_rows(pose, rows[:-1], depth, 9)


def test_branches_outside_a_beam_are_never_chosen(tiny):
    from frog_planner.core.tree_search import tree_from_rows
    states, table = tiny
    model = TransitionModel(states, table, list("ABCDEFGHI"))
    scale = [float(np.ptp(states[:, c])) for c in range(3)]
    path = sinusoid_path(length=0.36, A=8.5, f=10.0, start=(0.0, 0.0), heading=0.1)
    pose, vel, prev = (0.10, -0.03, -0.4), (0.035, -0.02, -0.3), 0.25
    rows = _reference_rows(states, table, pose, vel, 2, scale)
    best_first = ref_search(states, table, path, pose, vel, 2, "euclidean", 1, scale, prev)[0][0]
    beam = [a for a in range(9) if a != best_first][:3]       # a beam without the true best
    for a in range(9):
        if a not in beam:
            rows[9 + 9 * a:9 + 9 * (a + 1)] = np.nan
    result = search(model, path, pose, vel, 2, CostWeights(), prev,
                    expander=lambda p, v, d: tree_from_rows(p, rows, d, 9))
    _, _, leaves = ref_search(states, table, path, pose, vel, 2, "euclidean", 1, scale, prev)
    costs = {seq: ref_cost(path, leaf, prev) for seq, leaf in leaves.items() if seq[0] in beam}
    assert result.sequence == min(costs, key=costs.get)
    assert np.isinf(result.leaf_total).sum() == 81 - 27
    rows[:] = np.nan
    with pytest.raises(ValueError, match="no leaf"):
        search(model, path, pose, vel, 2, CostWeights(), prev, expander=lambda p, v, d: tree_from_rows(p, rows, d, 9))


@pytest.mark.parametrize("depth", [2, 3])
def test_stage_cost_sums_every_period_end_of_a_sequence(tiny, depth):
    """stage_cost: each sequence costs eq. 19 at each of its period ends, summed (brute force:
    the reference chain and the reference cost at every step), from the library and from given
    rows alike; an expander without levels is refused."""
    from frog_planner.core.tree_search import tree_from_rows
    states, table = tiny
    model = TransitionModel(states, table, list("ABCDEFGHI"))
    scale = [float(np.ptp(states[:, c])) for c in range(3)]
    path = sinusoid_path(length=0.36, A=8.5, f=10.0, start=(0.0, 0.0), heading=0.1)
    pose, vel, prev = (0.10, -0.03, -0.4), (0.035, -0.02, -0.3), 0.25
    want = {}
    for seq in itertools.product(range(9), repeat=depth):
        p, v, total = pose, vel, 0.0
        for a in seq:
            p, v = ref_step(p, ref_transition(table, a, ref_nearest(states, v, "euclidean", scale, 1)))
            total += ref_cost(path, p, prev)
        want[seq] = total
    best = min(want, key=want.get)
    rows = _reference_rows(states, table, pose, vel, depth, scale)
    for expander in (None, lambda p, v, d: tree_from_rows(p, rows, d, 9)):
        result = search(model, path, pose, vel, depth, CostWeights(), prev, expander=expander, stage_cost=True)
        np.testing.assert_allclose(result.leaf_total, [want[s] for s in itertools.product(range(9), repeat=depth)],
                                   rtol=1e-9)
        assert result.sequence == best and result.total_cost == pytest.approx(want[best], rel=1e-9)
    leaf_only = search(model, path, pose, vel, depth, CostWeights(), prev)
    assert leaf_only.total_cost < result.total_cost           # the leaf is one of the summed ends
    with pytest.raises(ValueError, match="every level"):
        search(model, path, pose, vel, depth, CostWeights(), prev, stage_cost=True,
               expander=lambda p, v, d: tree_from_rows(p, rows, d, 9)[:3])


def test_reanchored_rows_chained_from_the_lead_s_end_are_the_original_tree():
    """Chaining reanchored rows from where the lead ended (computed here by composing the lead's
    transition onto the request pose) gives the original tree's leaves and levels; from another
    pose, the same tree moved rigidly with it."""
    from frog_planner.core.prediction import apply_transition
    from frog_planner.core.tree_search import reanchor_rows, tree_from_rows
    rng = np.random.default_rng(5)
    rows = rng.normal(0, 0.02, (9 + 81, 6))
    lead = np.array([0.012, -0.004, 0.2, 0.01, 0.0, 0.05])
    pose = np.array([0.1, -0.2, 0.7])
    end, _ = apply_transition(pose, lead[None, :])
    original = tree_from_rows(pose, rows, 2, 9)
    moved = reanchor_rows(rows, lead, 9)
    anchored = tree_from_rows(end[0], moved, 2, 9)
    np.testing.assert_allclose(anchored[0], original[0], atol=1e-12)
    np.testing.assert_allclose(anchored[1], original[1], atol=1e-12)
    np.testing.assert_array_equal(moved[9:], rows[9:])
    # from a pose 1 cm left and 0.1 rad more: the leaves move with it, rigidly
    other = end[0] + np.array([-0.01 * math.sin(end[0, 2]), 0.01 * math.cos(end[0, 2]), 0.1])
    shifted = tree_from_rows(other, moved, 2, 9)[0]
    def rel(base, p):
        c, s = np.cos(base[2]), np.sin(base[2])
        return np.column_stack([c * (p[:, 0] - base[0]) + s * (p[:, 1] - base[1]),
                                -s * (p[:, 0] - base[0]) + c * (p[:, 1] - base[1])])
    np.testing.assert_allclose(rel(other, shifted), rel(end[0], original[0]), atol=1e-12)
    with pytest.raises(ValueError, match="6 finite"):
        reanchor_rows(rows, [0.0] * 5, 9)
