"""Real-time factor of one frog simulation on one core (issue 3, Performance).

Frog with 10 % EGaIn limbs swimming the 1 Hz gait (phase 0.5) at the default time
step and resolution. Measures, in the same run:

* the library path (numba kernels, sparse LU plan, simplified Newton), and
* a straightforward numpy/scipy.sparse version of the same step
  (``frog_sim.core.reference_numpy``: vectorised numpy, COO->CSR, spsolve, full Newton),

and prints medians of repeated runs, their ratio, the agreement of the two final
states, and the peak RSS of the process. Real-time factors are given from wall time
and from the CPU time of the process (``time.process_time``): on a shared machine the
CPU-time figure is the one-core cost, the wall-time figure includes waiting for the CPU.

Run: ``./dev bench frog_sim_realtime`` (or ``./dev run python bench/frog_sim_realtime.py``).
"""
from __future__ import annotations

import os

for _var in ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS', 'NUMBA_NUM_THREADS'):
    os.environ.setdefault(_var, '1')

import argparse  # noqa: E402
import resource  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402


def pin_to_one_core() -> str:
    """Pin the process to one CPU (the first allowed) so the figure is a one-core figure."""
    try:
        cpus = sorted(os.sched_getaffinity(0))
        os.sched_setaffinity(0, {cpus[-1]})
        return f'pinned to CPU {cpus[-1]} of {cpus}'
    except (AttributeError, OSError):  # pragma: no cover - non-Linux
        return 'not pinned (sched_setaffinity unavailable)'


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--sim-seconds', type=float, default=10.0, help='simulated seconds per library run')
    parser.add_argument('--repeats', type=int, default=5, help='library runs (median reported)')
    parser.add_argument('--numpy-seconds', type=float, default=0.5, help='simulated seconds per numpy run')
    parser.add_argument('--numpy-repeats', type=int, default=3)
    args = parser.parse_args()
    pin = pin_to_one_core()

    from frog_sim.core.actuation import ActuationLibrary
    from frog_sim.core.reference_numpy import NumpyReferenceStepper
    from frog_sim.core.simulation import DEFAULT_TIME_STEP, FrogSimulation
    lib = ActuationLibrary.load()
    dt = DEFAULT_TIME_STEP

    from frog_sim.core.model_parameters import FrogParameters
    undamped = FrogParameters().replace(surge_damping_linear=0.0, sway_damping_linear=0.0, yaw_damping_linear=0.0)

    def fresh_sim(params=None):
        sim = FrogSimulation(params, library=lib)
        sim.set_gait(1.0, 0.5)
        return sim

    # warm-up: numba compilation / cache load
    t0 = time.perf_counter()
    fresh_sim().step(10)
    warm = time.perf_counter() - t0

    n_steps = int(round(args.sim_seconds / dt))
    rtf, rtf_cpu, per_step, iters, facts = [], [], [], [], []
    rtf0, rtf0_cpu = [], []     # the same without the lumped body damping (issue 18), interleaved
    for _ in range(args.repeats):
        sim = fresh_sim(undamped)
        t0, c0 = time.perf_counter(), time.process_time()
        sim.step(n_steps)
        rtf0.append(args.sim_seconds / (time.perf_counter() - t0))
        rtf0_cpu.append(args.sim_seconds / (time.process_time() - c0))
        sim = fresh_sim()
        t0 = time.perf_counter()
        c0 = time.process_time()
        sim.step(n_steps)
        wall = time.perf_counter() - t0
        rtf_cpu.append(args.sim_seconds / (time.process_time() - c0))
        rtf.append(args.sim_seconds / wall)
        per_step.append(wall / n_steps * 1e6)
        iters.append(sim.integrator.stats.newton_iterations / n_steps)
        facts.append(sim.integrator.factorizations / n_steps)
    # the same steps with the numpy/scipy baseline, from the same state
    n_np = int(round(args.numpy_seconds / dt))
    np_rtf, np_rtf_cpu, np_step, diffs = [], [], [], []
    for _ in range(args.numpy_repeats):
        sim = fresh_sim()
        integ = sim.integrator
        ref = NumpyReferenceStepper(integ.network, integ.mass, actuator=integ.actuator,
                                    force_tolerance=integ.force_tolerance, body_damping=integ.body_damping,
                                    reference=integ.reference)
        ref.x[:] = integ.x
        t0 = time.perf_counter()
        c0 = time.process_time()
        for _ in range(n_np):
            ref.step(dt)
        wall = time.perf_counter() - t0
        np_rtf_cpu.append(args.numpy_seconds / (time.process_time() - c0))
        np_rtf.append(args.numpy_seconds / wall)
        np_step.append(wall / n_np * 1e6)
        sim.step(n_np)
        diffs.append(float(np.abs(ref.x - sim.integrator.x).max()))
    med = statistics.median
    peak_rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    model = fresh_sim().model
    print('frog_sim real-time benchmark (10 % EGaIn, 1 Hz gait, phase 0.5)')
    print(f'  {pin}; nodes {model.n_nodes}, dt {dt * 1e3:g} ms, warm-up/compile {warm:.2f} s')
    print(f'  library (numba, sparse LU plan, simplified Newton): median real-time factor '
          f'{med(rtf_cpu):.1f}x by CPU time, {med(rtf):.1f}x by wall time '
          f'(wall min {min(rtf):.1f}x, max {max(rtf):.1f}x) over {args.repeats} x {args.sim_seconds:g} sim s; '
          f'{med(per_step):.1f} us/step (wall), {med(iters):.2f} Newton iterations/step, '
          f'{med(facts):.2f} LU factorisations/step')
    print(f'  without the lumped body damping (issue 18), same run: {med(rtf0_cpu):.1f}x by CPU time, '
          f'{med(rtf0):.1f}x by wall time; with / without {med(rtf_cpu) / med(rtf0_cpu):.3f} (CPU), '
          f'{med(rtf) / med(rtf0):.3f} (wall)')
    print(f'  numpy/scipy.sparse baseline (full Newton, spsolve): median real-time factor '
          f'{med(np_rtf_cpu):.2f}x by CPU time, {med(np_rtf):.2f}x by wall time over '
          f'{args.numpy_repeats} x {args.numpy_seconds:g} sim s; {med(np_step):.0f} us/step (wall)')
    print(f'  speed-up library / baseline: {med(rtf_cpu) / med(np_rtf_cpu):.1f}x by CPU time, '
          f'{med(rtf) / med(np_rtf):.1f}x by wall time '
          f'(same steps: max |x_lib - x_numpy| = {max(diffs):.2e} m after {args.numpy_seconds:g} s)')
    print(f'  target >= 30x real time (CPU time): {"met" if med(rtf_cpu) >= 30 else "NOT met"}; '
          f'stretch 100x: {"met" if med(rtf_cpu) >= 100 else "not met"}')
    print(f'  peak RSS of this process: {peak_rss_mb:.0f} MB')


if __name__ == '__main__':
    main()
