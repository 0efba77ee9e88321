"""Planner decision latency with a paper-size library (8503 initial states x 9 primitives, T = 1.5 s).

One decision = ``Planner.decide(pose, body_velocity)``: monotone progress of the measured pose,
nearest-neighbour lookups, eq. 18 predictions of all 9^H sequences, eq. 19 at the leaves.
Poses walk along the paper's ellipse with noise. Targets: median <= 1 ms at depth 1
and <= 20 ms at depth 3 over 1,000 decisions.

The same decisions are also made by a straightforward implementation measured in the same run:
Python loops over every action sequence and step (itertools.product), a brute-force neighbour
search over the whole library at every node (numpy over the states, as in the authors' code),
and the cost by a loop over the path segments. It is slow, so it runs on fewer decisions
(medians still); its decisions are checked to be the same as the planner's.

    ./dev run python bench/planner_latency.py [--decisions 1000] [--loop-decisions 100 10] [--metric euclidean]
"""

import argparse
import itertools
import math
import statistics
import sys
import time

import numpy as np
from frog_common.primitives import PRIMITIVE_NAMES
from frog_planner.core.paths import ellipse_path
from frog_planner.core.planner import Planner
from frog_planner.core.settings import PlannerSettings
from frog_planner.core.transition_model import TransitionModel

N_STATES = 8503          # paper: 8503 simulations per action
NAMES = list(PRIMITIVE_NAMES)
PERIOD = 1.5             # s


def paper_size_library(seed=0):
    """Initial states in the paper's ranges and plausible transitions after T (constant-twist motion).

    Returns initial_states (N, 3) in m/s, m/s, rad/s and transitions (9, N, 6) in m, m, rad, m/s, m/s, rad/s.
    """
    rng = np.random.default_rng(seed)
    init = np.column_stack([rng.uniform(0.0, 0.04, N_STATES), rng.uniform(-0.03, 0.03, N_STATES),
                            rng.uniform(-np.pi / 6, np.pi / 6, N_STATES)])
    # Each primitive adds a forward speed and a yaw rate; noise stands in for the simulator's detail.
    push = np.array([[0.03, 0.0], [0.04, 0.0], [0.015, 0.35], [0.015, -0.35], [0.02, 0.15], [0.02, -0.15],
                     [0.005, 0.5], [0.005, -0.5], [0.0, 0.0]])
    trans = np.empty((9, N_STATES, 6))
    for p, (du, dw) in enumerate(push):
        u = 0.5 * (init[:, 0] + du) + rng.normal(0, 0.002, N_STATES)
        w = 0.5 * (init[:, 2] + dw) + rng.normal(0, 0.02, N_STATES)
        dth = w * PERIOD
        chord = np.where(np.abs(w) > 1e-9, 2.0 * u / np.where(np.abs(w) > 1e-9, w, 1.0) * np.sin(dth / 2), u * PERIOD)
        trans[p] = np.column_stack([chord * np.cos(dth / 2), chord * np.sin(dth / 2) + 0.3 * init[:, 1] * PERIOD, dth,
                                    u, 0.5 * init[:, 1], w])
    return init, trans


def query_stream(path, n, seed=1):
    """n (pose, body velocity) pairs walking along the path with noise."""
    rng = np.random.default_rng(seed)
    s = np.linspace(0.0, 0.95, n)
    xy = path.point_at(s) + rng.normal(0.0, 0.01, (n, 2))
    heading = path.tangent_heading_at(s) + rng.normal(0.0, 0.2, n)
    poses = np.column_stack([xy, heading])
    vel = np.column_stack([rng.uniform(0.0, 0.04, n), rng.uniform(-0.02, 0.02, n), rng.uniform(-0.4, 0.4, n)])
    return poses, vel


class LoopPlanner:
    """Straightforward reference: per-sequence Python loops, brute-force neighbour search per node."""

    def __init__(self, init, trans, path, depth, scale, metric="euclidean", weights=(500.0, 50.0, 300.0)):
        self.init, self.trans, self.path, self.depth = init, trans, path, depth
        self.scale = np.asarray(scale)
        self.metric = metric
        self.weights = weights
        self.progress = 0.0
        self.unwrapped = np.unwrap(path.tangent_headings)

    def nearest(self, v):
        v = np.asarray(v)
        # Scaled Euclidean, or Algorithm 1 step 6 with the denominators floored at 5 % of the scale.
        denom = self.scale if self.metric == "euclidean" else np.maximum(np.abs(v), 0.05 * self.scale)
        d = np.sqrt((((v - self.init) / denom) ** 2).sum(axis=1))
        return int(np.argmin(d))

    def closest(self, x, y, prev):
        pts, arc, L = self.path.points, self.path.arc_length, self.path.length
        s0 = prev * L
        s1 = min(s0 + self.path.progress_window, L)
        best_d, best_s = math.inf, s0
        for i in range(len(pts) - 1):
            lo, hi = max(arc[i], s0), min(arc[i + 1], s1)
            if lo > hi:
                continue
            seg = arc[i + 1] - arc[i]
            ax = pts[i, 0] + (lo - arc[i]) / seg * (pts[i + 1, 0] - pts[i, 0])
            ay = pts[i, 1] + (lo - arc[i]) / seg * (pts[i + 1, 1] - pts[i, 1])
            bx = pts[i, 0] + (hi - arc[i]) / seg * (pts[i + 1, 0] - pts[i, 0])
            by = pts[i, 1] + (hi - arc[i]) / seg * (pts[i + 1, 1] - pts[i, 1])
            dx, dy = bx - ax, by - ay
            den = dx * dx + dy * dy
            t = 0.0 if den == 0 else min(1.0, max(0.0, ((x - ax) * dx + (y - ay) * dy) / den))
            d = math.hypot(x - ax - t * dx, y - ay - t * dy)
            if d < best_d:
                best_d, best_s = d, lo + t * (hi - lo)
        return best_d, best_s / L

    def cost(self, pose, prev):
        d, s = self.closest(pose[0], pose[1], prev)
        tangent = np.interp(s * self.path.length, self.path.arc_length, self.unwrapped)
        err = abs((pose[2] - tangent + math.pi) % (2 * math.pi) - math.pi)
        return self.weights[0] * d + self.weights[1] * err + self.weights[2] * (1.0 - s)

    def decide(self, pose, vel):
        _, s = self.closest(pose[0], pose[1], self.progress)
        self.progress = max(self.progress, s)
        best, best_seq = math.inf, None
        for seq in itertools.product(range(9), repeat=self.depth):
            x, y, th = pose
            v = vel
            for a in seq:
                t = self.trans[a, self.nearest(v)]
                c, sn = math.cos(th), math.sin(th)
                x, y, th = x + c * t[0] - sn * t[1], y + sn * t[0] + c * t[1], th + t[2]
                v = t[3:6]
            cost = self.cost((x, y, th), self.progress)
            if cost < best:
                best, best_seq = cost, seq
        return best_seq


def time_decisions(decide, poses, vels):
    """Wall time of each decision in s, and the decisions."""
    times, out = [], []
    for pose, vel in zip(poses, vels):
        t0 = time.perf_counter()
        out.append(decide(pose, vel))
        times.append(time.perf_counter() - t0)
    return np.array(times), out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--decisions", type=int, default=1000, help="decisions per depth for the planner")
    ap.add_argument("--loop-decisions", type=int, nargs=2, default=[100, 10], metavar=("DEPTH1", "DEPTH3"),
                    help="decisions for the loop reference at depth 1 and 3")
    ap.add_argument("--metric", choices=["euclidean", "relative"], default="euclidean")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)

    init, trans = paper_size_library(args.seed)
    t0 = time.perf_counter()
    model = TransitionModel(init, trans, NAMES, period=PERIOD, metric=args.metric)
    build_ms = 1e3 * (time.perf_counter() - t0)
    path = ellipse_path()
    print(f"library: {model.n_states} initial states x {model.n_primitives} primitives, T = {PERIOD} s, "
          f"metric {args.metric}; model built in {build_ms:.1f} ms; path {path.name} {path.length:.3f} m")
    # The loop reference implements the paper's planner (eq. 19 at the leaf, tangent heading,
    # nearest-state transitions), so the like-for-like timing uses PlannerSettings.paper(); the defaults
    # (look-aheads, gradient correction, stall guard) are timed separately below.
    corrected = TransitionModel(init, trans, NAMES, period=PERIOD, metric=args.metric, gradient_correction=True)
    print(f"{'depth':>5} {'sequences':>9} {'planner median':>15} {'p90':>9} {'n':>5} {'loop median':>12} {'n':>4} "
          f"{'speed-up':>9} {'same':>6} {'target':>7} {'defaults median':>16}")
    ok = True
    for depth, n_loop, target_ms in [(1, args.loop_decisions[0], 1.0), (3, args.loop_decisions[1], 20.0)]:
        poses, vels = query_stream(path, args.decisions, seed=args.seed + depth)
        planner = Planner(model, path, PlannerSettings.paper(depth=depth))
        for pose, vel in zip(poses[:20], vels[:20]):     # warm-up (imports, caches)
            planner.decide(pose, vel)
        planner.reset()
        t_fast, decisions = time_decisions(lambda p, v: planner.decide(p, v).sequence, poses, vels)
        default = Planner(corrected, path, PlannerSettings(depth=depth))
        for pose, vel in zip(poses[:20], vels[:20]):
            default.decide(pose, vel)
        default.reset()
        t_default, _ = time_decisions(lambda p, v: default.decide(p, v).sequence, poses, vels)
        med_default = 1e3 * statistics.median(t_default)
        ok &= med_default <= target_ms
        loop_ids = np.linspace(0, args.decisions - 1, n_loop).astype(int)
        same = 0
        t_loop = []
        planner.reset()
        for i in loop_ids:
            # The loop reference starts from the planner's progress before that decision.
            ref = LoopPlanner(init, trans, path, depth, model.scale, args.metric)
            ref.progress = _progress_before(path, poses, i)
            t, (seq,) = time_decisions(ref.decide, poses[i:i + 1], vels[i:i + 1])
            t_loop.append(t[0])
            same += seq == decisions[i]
        same_text = f"{same}/{len(loop_ids)}"
        ok &= same == len(loop_ids)
        med = 1e3 * statistics.median(t_fast)
        med_loop = 1e3 * statistics.median(t_loop)
        ok &= med <= target_ms
        print(f"{depth:>5} {9 ** depth:>9} {med:>12.3f} ms {1e3 * np.percentile(t_fast, 90):>6.3f} ms "
              f"{len(t_fast):>5} {med_loop:>9.1f} ms {len(t_loop):>4} {med_loop / med:>8.0f}x {same_text:>6} "
              f"{'<= ' + format(target_ms, 'g'):>7} {med_default:>13.3f} ms")
    print("targets met" if ok else "TARGET MISSED or decisions differ")
    return 0 if ok else 1


def _progress_before(path, poses, i):
    """Monotone progress the planner holds before decision i (replays the pose stream)."""
    progress = 0.0
    for pose in poses[:i]:
        progress = path.progress_of(pose, progress)
    return progress


if __name__ == "__main__":
    sys.exit(main())
