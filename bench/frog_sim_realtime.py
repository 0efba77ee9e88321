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

``--compare-ref REF`` (e.g. ``main``) instead measures the library path of this tree against
the one of git revision REF in the same run: each measurement is a fresh subprocess whose
``PYTHONPATH`` starts with the ``frog_sim`` source tree of one side (REF's is exported with
``git archive`` into ``~/.cache/frog_sim/bench_trees/<sha>``, or given by ``--ref-tree``),
both sides alternate (ABBA), each subprocess warms up (numba cache load) before its timed
run, and both read the same measurements (``FROG_DATA_DIR``). Each side compiles once into
an empty numba cache of its own for the run (numba does not notice a stale cache of a
function whose callees changed in another module). It prints the median
CPU-time and wall-time real-time factors of each side, their ratio (this / REF; >= 1: this
tree is not slower), the median of the per-pair ratios, and the largest difference of the
two sides' final states.
"""
from __future__ import annotations

import os

for _var in ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS', 'NUMBA_NUM_THREADS'):
    os.environ.setdefault(_var, '1')

import argparse  # noqa: E402
import io  # noqa: E402
import json  # noqa: E402
import resource  # noqa: E402
import shutil  # noqa: E402
import statistics  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tarfile  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402


def pin_to_one_core() -> str:
    """Pin the process to one CPU (the first allowed) so the figure is a one-core figure."""
    try:
        cpus = sorted(os.sched_getaffinity(0))
        os.sched_setaffinity(0, {cpus[-1]})
        return f'pinned to CPU {cpus[-1]} of {cpus}'
    except (AttributeError, OSError):  # pragma: no cover - non-Linux
        return 'not pinned (sched_setaffinity unavailable)'


REPO = Path(__file__).resolve().parents[1]
PACKAGE_DIR = 'ros_ws/src/frog_sim'      # the frog_sim source tree inside the repository


def measure_once(sim_seconds: float, damped: bool = True) -> dict:
    """One timed library run of the bench's gait in this process, after a warm-up."""
    from frog_sim.core.actuation import ActuationLibrary
    from frog_sim.core.model_parameters import FrogParameters
    from frog_sim.core.simulation import DEFAULT_TIME_STEP, FrogSimulation
    lib = ActuationLibrary.load()
    params = FrogParameters()
    if not damped:
        params = params.replace(surge_damping_linear=0.0, sway_damping_linear=0.0, yaw_damping_linear=0.0)
    t0 = time.perf_counter()
    warm = FrogSimulation(params, library=lib)
    warm.set_gait(1.0, 0.5)
    warm.step(10)
    warm_s = time.perf_counter() - t0
    sim = FrogSimulation(params, library=lib)
    sim.set_gait(1.0, 0.5)
    n_steps = int(round(sim_seconds / DEFAULT_TIME_STEP))
    t0, c0 = time.perf_counter(), time.process_time()
    sim.step(n_steps)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    import frog_sim
    return {'rtf_wall': sim_seconds / wall, 'rtf_cpu': sim_seconds / cpu, 'warm_s': warm_s,
            'iters': sim.integrator.stats.newton_iterations / n_steps,
            'facts': sim.integrator.factorizations / n_steps,
            'x': sim.integrator.x.tolist(), 'source': str(Path(frog_sim.__file__).resolve().parent)}


def export_tree(ref: str) -> tuple[Path, str]:
    """``frog_sim`` source tree of git revision ``ref`` (exported once per commit); (tree, sha)."""
    sha = subprocess.run(['git', '-C', str(REPO), 'rev-parse', '--verify', f'{ref}^{{commit}}'], check=True,
                         capture_output=True, text=True).stdout.strip()
    root = Path(os.environ.get('FROG_SIM_CACHE_DIR', Path.home() / '.cache' / 'frog_sim')) / 'bench_trees' / sha
    if not (root / PACKAGE_DIR / 'frog_sim' / '__init__.py').is_file():
        root.mkdir(parents=True, exist_ok=True)
        archive = subprocess.run(['git', '-C', str(REPO), 'archive', '--format=tar', sha, PACKAGE_DIR],
                                 check=True, capture_output=True).stdout
        with tarfile.open(fileobj=io.BytesIO(archive)) as tar:
            tar.extractall(root, filter='data')
    return root / PACKAGE_DIR, sha


def run_worker(tree: Path, sim_seconds: float, damped: bool, numba_cache: Path) -> dict:
    """:func:`measure_once` in a fresh subprocess importing ``frog_sim`` from ``tree``, with
    numba's cache in ``numba_cache``."""
    from frog_sim.core.actuation import find_data_dir
    env = dict(os.environ)
    env['PYTHONPATH'] = os.pathsep.join([str(tree)] + [p for p in env.get('PYTHONPATH', '').split(os.pathsep) if p])
    env.setdefault('FROG_DATA_DIR', str(find_data_dir()))
    env['NUMBA_CACHE_DIR'] = str(numba_cache)
    cmd = [sys.executable, str(Path(__file__).resolve()), '--worker', '--sim-seconds', str(sim_seconds)]
    if not damped:
        cmd.append('--undamped')
    out = subprocess.run(cmd, env=env, check=True, capture_output=True, text=True).stdout
    result = json.loads(out.strip().splitlines()[-1])
    if Path(result['source']) != (tree / 'frog_sim').resolve():
        raise RuntimeError(f'the worker imported frog_sim from {result["source"]}, expected {tree}')
    return result


def compare(args) -> None:
    """This tree against git revision ``args.compare_ref``, alternating subprocesses (ABBA)."""
    pin = pin_to_one_core()      # inherited by the workers
    if args.ref_tree:
        ref_tree, ref_name = Path(args.ref_tree).resolve() / PACKAGE_DIR, f'{args.compare_ref} at {args.ref_tree}'
    else:
        ref_tree, sha = export_tree(args.compare_ref)
        ref_name = f'{args.compare_ref} ({sha[:8]})'
    head = subprocess.run(['git', '-C', str(REPO), 'describe', '--always', '--dirty'], capture_output=True,
                          text=True).stdout.strip()
    this_tree = REPO / PACKAGE_DIR
    sides = {'ref': ref_tree, 'this': this_tree}
    # numba's cache checks only the source file of a cached function, not the modules of the
    # kernels it calls: a tree's own __pycache__ can hold an integrator compiled with older
    # kernels. Each side gets an empty cache for this run, filled by one untimed first run.
    caches = {side: Path(tempfile.mkdtemp(prefix=f'frog_sim_bench_numba_{side}_')) for side in sides}
    compile_s = {}
    try:
        for side, tree in sides.items():
            t0 = time.perf_counter()
            run_worker(tree, 0.1, not args.undamped, caches[side])
            compile_s[side] = time.perf_counter() - t0
        results = {'ref': [], 'this': []}
        for i in range(args.repeats):
            for side in (('ref', 'this') if i % 2 == 0 else ('this', 'ref')):
                results[side].append(run_worker(sides[side], args.sim_seconds, not args.undamped, caches[side]))
            r, t = results['ref'][-1], results['this'][-1]
            print(f'  pair {i + 1}/{args.repeats}: CPU RTF ref {r["rtf_cpu"]:.1f}x this {t["rtf_cpu"]:.1f}x, '
                  f'wall ref {r["rtf_wall"]:.1f}x this {t["rtf_wall"]:.1f}x', flush=True)
    finally:
        for cache in caches.values():
            shutil.rmtree(cache, ignore_errors=True)
    med = statistics.median

    def stat(side, key):
        return med(res[key] for res in results[side])
    pair_cpu = [t['rtf_cpu'] / r['rtf_cpu'] for r, t in zip(results['ref'], results['this'])]
    pair_wall = [t['rtf_wall'] / r['rtf_wall'] for r, t in zip(results['ref'], results['this'])]
    diff = max(float(np.abs(np.subtract(r['x'], t['x'])).max()) for r, t in zip(results['ref'], results['this']))
    gait = 'without' if args.undamped else 'with'
    print(f'frog_sim real-time factor, this tree ({head}) vs {ref_name}: 10 % EGaIn, 1 Hz gait, phase 0.5, '
          f'{gait} the lumped body damping')
    print(f'  {pin}; {args.repeats} fresh subprocesses per side, alternating (ABBA), '
          f'{args.sim_seconds:g} sim s each after a warm-up (warm-up median ref {stat("ref", "warm_s"):.2f} s, '
          f'this {stat("this", "warm_s"):.2f} s: numba cache loads); first run into an empty numba cache '
          f'(compilation) ref {compile_s["ref"]:.0f} s, this {compile_s["this"]:.0f} s')
    for side, name in (('ref', ref_name), ('this', f'this tree ({head})')):
        print(f'  {name}: median RTF {stat(side, "rtf_cpu"):.1f}x by CPU time, {stat(side, "rtf_wall"):.1f}x by wall '
              f'time; {stat(side, "iters"):.2f} Newton iterations/step, {stat(side, "facts"):.2f} LU '
              f'factorisations/step')
    print(f'  ratio this / ref of the medians: {stat("this", "rtf_cpu") / stat("ref", "rtf_cpu"):.3f} (CPU), '
          f'{stat("this", "rtf_wall") / stat("ref", "rtf_wall"):.3f} (wall); median of the per-pair ratios '
          f'{med(pair_cpu):.3f} (CPU, min {min(pair_cpu):.3f}, max {max(pair_cpu):.3f}), {med(pair_wall):.3f} (wall)')
    print(f'  same steps: max |x_this - x_ref| = {diff:.2e} m after {args.sim_seconds:g} s')


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--sim-seconds', type=float, default=10.0, help='simulated seconds per library run')
    parser.add_argument('--repeats', type=int, default=5, help='library runs (median reported); with '
                        '--compare-ref: subprocesses per side')
    parser.add_argument('--numpy-seconds', type=float, default=0.5, help='simulated seconds per numpy run')
    parser.add_argument('--numpy-repeats', type=int, default=3)
    parser.add_argument('--compare-ref', metavar='REF', help='compare the library path with git revision REF '
                        '(e.g. main) in alternating subprocesses instead')
    parser.add_argument('--ref-tree', metavar='DIR', help='with --compare-ref: a checkout of REF to use '
                        '(default: git archive of REF into ~/.cache/frog_sim/bench_trees/)')
    parser.add_argument('--undamped', action='store_true', help='with --compare-ref: the gait without the '
                        'lumped body damping')
    parser.add_argument('--worker', action='store_true', help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        print(json.dumps(measure_once(args.sim_seconds, not args.undamped)))
        return
    if args.compare_ref:
        compare(args)
        return
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
