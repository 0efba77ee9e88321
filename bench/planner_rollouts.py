"""Batched DER rollouts for a planner decision against FrogSimulation.step.

Measured in the same run, medians over ``--repeats`` (the two methods alternate within each
repeat, so both see the same machine load; CPU time is the process's, all threads):

* the baseline: ``FrogSimulation.step`` simulating one period of one primitive from a start
  state at its default step (2 ms) and tolerance, one rollout at a time;
* ``Rollouts.rollout_batch`` (frog_sim/core/rollouts.py): a depth-1 decision (the 9
  primitives) and a depth-2 decision (the 81 pairs: 9 + 81 = 90 simulated periods), from an
  estimated start (tracked pose, body twist, limb firing times);
* throughput of both in simulated seconds per CPU second and per wall second (a depth-2
  decision counts its 90 distinct periods), their ratio, and the wall time of the decisions
  against the budget of 0.7 periods;
* a depth-2 decision under an estimated tank yaw torque (rollout_node's default: forces
  recomputed every 20 ms);
* the rollouts' error against the baseline from the same start states (the cost of the
  coarser step plan and tolerance);
* what the estimated start loses against the exact one: states taken from a running
  simulation (the instants a planner decides at, and 0.3 s after a firing, limbs mid-stroke),
  the 9 one-period rollouts from the simulator's full state and from the estimate built from
  its pose, twist and firing times.

Example::

    ./dev run python bench/planner_rollouts.py --repeats 5
    ./dev run python bench/planner_rollouts.py --threads 1 --repeats 3   # one core
"""
from __future__ import annotations

import argparse
import math
import os
import statistics
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from frog_sim.core.actuation import ActuationLibrary
from frog_sim.core.rollouts import Rollouts
from frog_common.primitives import LIMB_NAMES, PRIMITIVE_NAMES
from frog_sim.core.simulation import FrogSimulation
from frog_sim.core.yaw_disturbance import TANK_YAW_TORQUE_SD

PERIOD = 1.43            # s, the hardware's decision period
BUDGET_SHARE = 0.7       # of the period, for a decision
#: primitives the running simulation swims (decision states are taken after each)
SWIM = "BEEBFFBCDBGHBEB"


def running_states(ro, lib, period, n_decisions, n_mid):
    """Start states of a running swim, exact and estimated: at decision instants (just before
    the next primitive) and 0.3 s after a firing (limbs mid-stroke)."""
    sim = FrogSimulation(library=lib)
    sim.set_velocity(0.02, 0.0, 0.0)
    steps = int(round(period / sim.time_step))
    mid = int(round(0.3 / sim.time_step))
    decisions, strokes = [], []
    for k, prim in enumerate(SWIM):
        sim.execute_primitive(prim)
        if k % 2 == 1 and len(strokes) < n_mid:
            sim.step(mid)
            strokes.append(snapshot(ro, sim))
            sim.step(steps - mid)
        else:
            sim.step(steps)
        if k >= 1 and len(decisions) < n_decisions:
            decisions.append(snapshot(ro, sim))
    return decisions, strokes


def snapshot(ro, sim):
    """Starts from a running simulator: its full state, and the estimate from what a robot
    would know of it (pose, body twist, when each limb last fired)."""
    st = sim.rigid_body_state()
    last = {}
    for limb in LIMB_NAMES:
        t = sim.schedule.times(limb)
        t = t[t <= sim.time]
        if t.size:
            last[limb] = float(t[-1])
    estimate = ro.estimated_start([*st.com, st.heading], [*st.body_velocity, st.yaw_rate], last, now=sim.time)
    return {'exact': ro.start_from_simulation(sim), 'estimate': estimate}


def baseline_rollout(sim, start, prim, period):
    """One period of ``prim`` with FrogSimulation.step from ``start``; (transition, cpu s, wall s)."""
    sim.reset()
    sim.integrator.set_state(x=start.x, v=start.v)
    for lid, t in enumerate(start.last_firing):
        if np.isfinite(t):
            sim.fire_limbs([LIMB_NAMES[lid]], start=float(t))
    sim._unwrap.reset(start.pose[2])
    sim.execute_primitive(prim, start=0.0)
    n = int(round(period / sim.time_step))
    t0, c0 = time.perf_counter(), time.process_time()
    sim.step(n)
    cpu, wall = time.process_time() - c0, time.perf_counter() - t0
    st = sim.rigid_body_state()
    c, s = math.cos(start.pose[2]), math.sin(start.pose[2])
    d = st.com - start.pose[:2]
    row = [c * d[0] + s * d[1], -s * d[0] + c * d[1], st.heading - start.pose[2], *st.body_velocity, st.yaw_rate]
    return np.array(row), cpu, wall


def timed(fn):
    t0, c0 = time.perf_counter(), time.process_time()
    out = fn()
    return out, time.process_time() - c0, time.perf_counter() - t0


def errors(a, b):
    """Position [cm] and heading [deg] differences of transition rows (..., 6)."""
    d = np.asarray(a) - np.asarray(b)
    return np.hypot(d[..., 0], d[..., 1]).ravel() * 100.0, np.degrees(np.abs(d[..., 2])).ravel()


def describe(values, unit, digits=3):
    v = np.asarray(values)
    return (f'median {np.median(v):.{digits}f} {unit}, p90 {np.percentile(v, 90):.{digits}f}, '
            f'max {v.max():.{digits}f}')


#: first primitives of the beam timed beside the full depth-2 tree (planner_node beam_width)
BEAM = 3


def library_latency(library_file, period, repeats, starts):
    """The library mode's decision time (Planner.decide, default cost), beside the rollouts."""
    from frog_planner.core.paths import sinusoid_path
    from frog_planner.core.planner import Planner
    from frog_planner.core.settings import PlannerSettings
    from frog_planner.core.transition_model import TransitionModel
    if not library_file.is_file():
        print(f'  library mode: {library_file} not found (frog-twin generates it on first use); not timed')
        return
    model = TransitionModel.load(str(library_file), period=period)
    for depth in (1, 2):
        planner = Planner(model, sinusoid_path(), PlannerSettings(depth=depth))
        cpu, wall = [], []
        for _ in range(repeats):
            for start in starts:
                planner.reset()
                _, c, w = timed(lambda: planner.decide(start.pose, start.twist if start.twist is not None
                                                       else np.zeros(3)))
                cpu.append(c)
                wall.append(w)
        print(f'  library mode depth {depth} ({library_file.name}): {statistics.median(wall) * 1e3:.2f} ms wall, '
              f'{statistics.median(cpu) * 1e3:.2f} ms CPU per decision (median)')


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('--repeats', type=int, default=5, help='repeats of every timing (medians reported)')
    ap.add_argument('--threads', type=int, default=None, help='rollout threads (default: the CPUs this '
                    'process may use)')
    ap.add_argument('--period', type=float, default=PERIOD, help='primitive period [s] (default 1.43)')
    ap.add_argument('--states', type=int, default=3, help='start states of the timed decisions')
    ap.add_argument('--compare-states', type=int, default=6, help='running-simulation states of each kind '
                    'for the estimated-vs-exact start comparison')
    ap.add_argument('--library', type=Path, default=Path(__file__).resolve().parents[1] / 'runs' / 'library' /
                    'frog_default.npz', help='motion library of the library-mode timing')
    args = ap.parse_args(argv)
    if args.repeats < 1 or args.states < 1 or args.compare_states < 1 or not 0 < args.period <= 5:
        ap.error('--repeats, --states, --compare-states must be >= 1 and --period in (0, 5]')
    period = args.period
    lib = ActuationLibrary.load()
    t0 = time.perf_counter()
    ro = Rollouts(library=lib, threads=args.threads)
    baseline = FrogSimulation(library=lib)
    decisions, strokes = running_states(ro, lib, period, max(args.states, args.compare_states), args.compare_states)
    starts = [s['estimate'] for s in decisions[:args.states]]
    ro.rollout_batch(starts[0], [('B', 'C')], period=period)          # numba cache load / compile
    setup = time.perf_counter() - t0
    prims = [(p,) for p in PRIMITIVE_NAMES]
    pairs = [(a, b) for a in PRIMITIVE_NAMES for b in PRIMITIVE_NAMES]

    beam = [(a, b) for a in PRIMITIVE_NAMES[:BEAM] for b in PRIMITIVE_NAMES]
    base_cpu, base_wall, d1_cpu, d1_wall, d2_cpu, d2_wall, bm_cpu, bm_wall = [], [], [], [], [], [], [], []
    tq_cpu, tq_wall = [], []
    base_rows, batch_rows, stats = None, None, None
    for _ in range(args.repeats):
        rows, cpu, wall = [], 0.0, 0.0
        for start in starts:
            for (p,) in prims:
                row, c, w = baseline_rollout(baseline, start, p, period)
                rows.append(row)
                cpu += c
                wall += w
        base_rows = np.array(rows).reshape(len(starts), len(prims), 6)
        base_cpu.append(cpu / len(rows))                    # per simulated period
        base_wall.append(wall / len(rows))
        r1 = []
        for start in starts:
            res, c, w = timed(lambda: ro.rollout_batch(start, prims, period=period))
            d1_cpu.append(c)
            d1_wall.append(w)
            r1.append(res.transitions[:, 0])
            res, c, w = timed(lambda: ro.rollout_batch(start, pairs, period=period))
            d2_cpu.append(c)
            d2_wall.append(w)
            stats = res.stats
            _, c, w = timed(lambda: ro.rollout_batch(start, beam, period=period))
            bm_cpu.append(c)
            bm_wall.append(w)
            torqued = replace(start, yaw_torque=TANK_YAW_TORQUE_SD)
            _, c, w = timed(lambda: ro.rollout_batch(torqued, pairs, period=period))
            tq_cpu.append(c)
            tq_wall.append(w)
        batch_rows = np.array(r1)
    med = statistics.median
    b_cpu, b_wall = med(base_cpu), med(base_wall)
    n2 = len(prims) + len(pairs)                            # distinct periods of a depth-2 decision
    budget = BUDGET_SHARE * period
    rate = {'base cpu': period / b_cpu, 'base wall': period / b_wall,
            'd1 cpu': len(prims) * period / med(d1_cpu), 'd1 wall': len(prims) * period / med(d1_wall),
            'd2 cpu': n2 * period / med(d2_cpu), 'd2 wall': n2 * period / med(d2_wall)}
    load = os.getloadavg()
    print(f'planner rollouts: {ro.threads} rollout thread(s) on {len(os.sched_getaffinity(0))} CPU(s), '
          f'load average {load[0]:.2f} / {load[1]:.2f} / {load[2]:.2f}; period {period:g} s; '
          f'{args.repeats} repeats x {len(starts)} start states; set-up (model builds, numba cache) {setup:.1f} s')
    print(f'  step plan: {ro.kick_time_step * 1e3:g} ms for {ro.kick_window:g} s after the last firing, then <= '
          f'{ro.coast_time_step * 1e3:g} ms; Newton tolerance {ro._sims[0].integrator.force_tolerance:g} N '
          f'(baseline: {baseline.time_step * 1e3:g} ms, {baseline.integrator.force_tolerance:g} N)')
    print(f'  depth-2 decision: {stats["jobs"]} jobs, {stats["steps"]} steps '
          f'({stats["steps"] / n2:.0f} per period against {int(round(period / baseline.time_step))}), '
          f'{stats["newton_iterations"] / stats["steps"]:.2f} Newton iterations and '
          f'{stats["factorisations"] / stats["steps"]:.2f} LU factorisations per step, '
          f'{stats["fallbacks"]} fallbacks')
    print('  throughput [simulated s per CPU s | per wall s], medians:')
    print(f'    baseline FrogSimulation.step, one rollout at a time: {rate["base cpu"]:6.1f} | {rate["base wall"]:6.1f}'
          f'  ({b_cpu * 1e3:.1f} ms CPU, {b_wall * 1e3:.1f} ms wall per {period:g} s period)')
    print(f'    rollout_batch depth 1 (9 periods):               {rate["d1 cpu"]:6.1f} | {rate["d1 wall"]:6.1f}'
          f'  (ratio to baseline {rate["d1 cpu"] / rate["base cpu"]:.2f}x CPU, '
          f'{rate["d1 wall"] / rate["base wall"]:.2f}x wall)')
    print(f'    rollout_batch depth 2 ({n2} periods):              {rate["d2 cpu"]:6.1f} | {rate["d2 wall"]:6.1f}'
          f'  (ratio to baseline {rate["d2 cpu"] / rate["base cpu"]:.2f}x CPU, '
          f'{rate["d2 wall"] / rate["base wall"]:.2f}x wall)')
    print(f'  decision wall time (budget {BUDGET_SHARE:g} x {period:g} s = {budget:.2f} s), median [min-max]:')
    for name, wall, cpu, n in (('depth 1', d1_wall, d1_cpu, len(prims)), ('depth 2', d2_wall, d2_cpu, n2),
                               (f'depth 2, beam {BEAM}', bm_wall, bm_cpu, BEAM + len(beam)),
                               (f'depth 2 under a tank torque of {TANK_YAW_TORQUE_SD:g} N m', tq_wall, tq_cpu, n2)):
        verdict = 'within' if med(wall) <= budget else 'OVER'
        cores = med(c / w for c, w in zip(cpu, wall))
        print(f'    {name}: {med(wall):.3f} s wall [{min(wall):.3f}-{max(wall):.3f}], {med(cpu):.3f} s CPU '
              f'({cores:.2f} cores busy): {verdict} budget; baseline would take {n * b_wall:.2f} s wall '
              f'({n * b_cpu:.2f} s CPU) on one core')
    library_latency(args.library, period, args.repeats, starts)
    pos, hd = errors(batch_rows, base_rows)
    du = np.abs(batch_rows - base_rows)
    print(f'  rollouts vs baseline from the same starts (step plan + tolerance), {pos.size} one-period rollouts: '
          f'position {describe(pos * 10, "mm")}; heading {describe(hd, "deg")}; '
          f'twist max {du[..., 3:5].max() * 1e3:.3f} mm/s, {np.degrees(du[..., 5].max()):.3f} deg/s')

    print('  estimated start (pose + twist + fire times) vs the exact full state, 9 one-period rollouts each:')
    for name, states in (('decision instants', decisions[:args.compare_states]),
                         ('0.3 s after a firing', strokes[:args.compare_states])):
        exact_rows, est_rows = [], []
        for s in states:
            exact_rows.append(ro.rollout_batch(s['exact'], prims, period=period).transitions[:, 0])
            est_rows.append(ro.rollout_batch(s['estimate'], prims, period=period).transitions[:, 0])
        pos, hd = errors(est_rows, exact_rows)
        du = np.abs(np.array(est_rows) - np.array(exact_rows))
        print(f'    {name} ({len(states)} states): position {describe(pos, "cm")}; heading {describe(hd, "deg", 2)}; '
              f'end speed max {du[..., 3:5].max() * 100:.2f} cm/s, yaw rate max {np.degrees(du[..., 5].max()):.1f} '
              'deg/s')
    ro.close()


if __name__ == '__main__':
    main()
