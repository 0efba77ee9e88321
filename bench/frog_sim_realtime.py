"""Real-time factor of one frog simulation on one core.

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
the one of git revision REF in the same run: REF's ``frog_sim`` source tree is exported with
``git archive`` into ``~/.cache/frog_sim/bench_trees/<sha>`` (or given by ``--ref-tree``);
each of ``--repeats`` fresh worker processes imports this tree as ``frog_sim`` and REF's as
``frog_sim_ref`` (the package imports itself relatively), warms both up and runs them
alternately, ``--inner`` times each (which side starts alternates between processes too);
both read the same measurements (``FROG_DATA_DIR``) and a numba cache made empty for the
run (numba does not notice a stale cache of a function whose callees changed in another
module), filled by a first untimed worker whose warm-up times are the compile times. It
prints the median CPU-time and wall-time real-time factors of each side, their ratio
(this / REF; >= 1: this tree is not slower), the median and quartiles of the per-pair
ratios, and the largest difference of the two sides' final states.
"""
from __future__ import annotations

import os

for _var in ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS', 'NUMBA_NUM_THREADS'):
    os.environ.setdefault(_var, '1')

import argparse  # noqa: E402
import importlib  # noqa: E402
import importlib.util  # noqa: E402
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


def measure_once(sim_seconds: float, damped: bool = True, package: str = 'frog_sim') -> dict:
    """One timed library run of the bench's gait with the ``frog_sim`` imported as ``package``,
    after a warm-up (numba cache load or compile, timed as ``warm_s``)."""
    core = importlib.import_module(f'{package}.core')
    actuation = importlib.import_module(f'{package}.core.actuation')
    model_parameters = importlib.import_module(f'{package}.core.model_parameters')
    simulation = importlib.import_module(f'{package}.core.simulation')
    lib = actuation.ActuationLibrary.load()
    params = model_parameters.FrogParameters()
    if not damped:
        params = params.replace(surge_damping_linear=0.0, sway_damping_linear=0.0, yaw_damping_linear=0.0)
    t0 = time.perf_counter()
    warm = simulation.FrogSimulation(params, library=lib)
    warm.set_gait(1.0, 0.5)
    warm.step(10)
    warm_s = time.perf_counter() - t0
    sim = simulation.FrogSimulation(params, library=lib)
    sim.set_gait(1.0, 0.5)
    n_steps = int(round(sim_seconds / simulation.DEFAULT_TIME_STEP))
    t0, c0 = time.perf_counter(), time.process_time()
    sim.step(n_steps)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    return {'rtf_wall': sim_seconds / wall, 'rtf_cpu': sim_seconds / cpu, 'warm_s': warm_s,
            'iters': sim.integrator.stats.newton_iterations / n_steps,
            'facts': sim.integrator.factorizations / n_steps,
            'x': sim.integrator.x.tolist(), 'source': str(Path(core.__file__).resolve().parent.parent)}


REF_PACKAGE = 'frog_sim_ref'    # the reference tree's frog_sim, imported under this name beside ours


def import_as(package_dir: Path, name: str):
    """Import the package in ``package_dir`` (a ``frog_sim`` folder) under the name ``name``
    (its modules import each other relatively, so both trees can live in one process)."""
    spec = importlib.util.spec_from_file_location(name, package_dir / '__init__.py',
                                                  submodule_search_locations=[str(package_dir)])
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


def measure_pair(ref_tree: Path, sim_seconds: float, damped: bool, inner: int, first: str) -> dict:
    """``inner`` timed runs of each tree in this process, alternating (``first`` starts), after
    a warm-up of both: this tree is ``frog_sim`` (first on the path), the reference tree is
    imported as :data:`REF_PACKAGE`."""
    import_as(ref_tree / 'frog_sim', REF_PACKAGE)
    packages = {'this': 'frog_sim', 'ref': REF_PACKAGE}
    order = [first, 'ref' if first == 'this' else 'this']
    warm = {side: measure_once(0.02, damped, packages[side])['warm_s'] for side in order}
    out = {'ref': [], 'this': [], 'warm_s': warm}
    for j in range(inner):
        for side in (order if j % 2 == 0 else order[::-1]):
            out[side].append(measure_once(sim_seconds, damped, packages[side]))
    return out


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


def run_worker(ref_tree: Path, sim_seconds: float, damped: bool, numba_cache: Path, inner: int, first: str) -> dict:
    """:func:`measure_pair` in a fresh subprocess with numba's cache in ``numba_cache``."""
    from frog_sim.core.actuation import find_data_dir
    this_tree = REPO / PACKAGE_DIR
    env = dict(os.environ)
    env['PYTHONPATH'] = os.pathsep.join([str(this_tree)] + [p for p in env.get('PYTHONPATH', '').split(os.pathsep)
                                                            if p])
    env.setdefault('FROG_DATA_DIR', str(find_data_dir()))
    env['NUMBA_CACHE_DIR'] = str(numba_cache)
    cmd = [sys.executable, str(Path(__file__).resolve()), '--worker', str(ref_tree), '--sim-seconds', str(sim_seconds),
           '--inner', str(inner), '--first', first]
    if not damped:
        cmd.append('--undamped')
    out = subprocess.run(cmd, env=env, check=True, capture_output=True, text=True).stdout
    result = json.loads(out.strip().splitlines()[-1])
    for side, tree in (('this', this_tree), ('ref', ref_tree)):
        if Path(result[side][0]['source']) != (tree / 'frog_sim').resolve():
            raise RuntimeError(f'the worker ran {result[side][0]["source"]} as {side}, expected {tree}')
    return result


def compare(args) -> None:
    """This tree against git revision ``args.compare_ref``, alternating in each of a series of
    fresh subprocesses (which side starts alternates too)."""
    pin = pin_to_one_core()      # inherited by the workers
    if args.ref_tree:
        ref_tree, ref_name = Path(args.ref_tree).resolve() / PACKAGE_DIR, f'{args.compare_ref} at {args.ref_tree}'
    else:
        ref_tree, sha = export_tree(args.compare_ref)
        ref_name = f'{args.compare_ref} ({sha[:8]})'
    head = subprocess.run(['git', '-C', str(REPO), 'describe', '--always', '--dirty'], capture_output=True,
                          text=True).stdout.strip()
    fit = 'frog_sim/data/actuation_fit.json'     # read from this tree by both (importlib.resources)
    if (ref_tree / fit).read_bytes() != (REPO / PACKAGE_DIR / fit).read_bytes():
        print(f'  warning: {fit} differs between the trees; both sides use this tree\'s')
    # numba's cache checks only the source file of a cached function, not the modules of the
    # kernels it calls: a tree's own __pycache__ can hold an integrator compiled with older
    # kernels. The run gets an empty cache, filled by a first untimed worker.
    cache = Path(tempfile.mkdtemp(prefix='frog_sim_bench_numba_'))
    try:
        first = run_worker(ref_tree, 0.02, not args.undamped, cache, 1, 'ref')
        compile_s = first['warm_s']
        results = {'ref': [], 'this': []}
        for i in range(args.repeats):
            res = run_worker(ref_tree, args.sim_seconds, not args.undamped, cache, args.inner,
                             'ref' if i % 2 == 0 else 'this')
            for side in results:
                results[side] += res[side]
            ref_rtf, this_rtf = (' '.join(f'{r["rtf_cpu"]:.1f}' for r in res[side]) for side in ('ref', 'this'))
            print(f'  process {i + 1}/{args.repeats}: CPU RTF ref {ref_rtf}, this {this_rtf}', flush=True)
    finally:
        shutil.rmtree(cache, ignore_errors=True)
    med = statistics.median

    def stat(side, key):
        return med(res[key] for res in results[side])
    pair_cpu = [t['rtf_cpu'] / r['rtf_cpu'] for r, t in zip(results['ref'], results['this'])]
    pair_wall = [t['rtf_wall'] / r['rtf_wall'] for r, t in zip(results['ref'], results['this'])]
    diff = max(float(np.abs(np.subtract(r['x'], t['x'])).max()) for r, t in zip(results['ref'], results['this']))
    gait = 'without' if args.undamped else 'with'
    n = len(results['ref'])
    print(f'frog_sim real-time factor, this tree ({head}) vs {ref_name}: 10 % EGaIn, 1 Hz gait, phase 0.5, '
          f'{gait} the lumped body damping')
    print(f'  {pin}; {n} runs of {args.sim_seconds:g} sim s per side, alternating, in {args.repeats} fresh '
          f'processes of {args.inner} + {args.inner}; first run into an empty numba cache (compilation) ref '
          f'{compile_s["ref"]:.0f} s, this {compile_s["this"]:.0f} s')
    for side, name in (('ref', ref_name), ('this', f'this tree ({head})')):
        print(f'  {name}: median RTF {stat(side, "rtf_cpu"):.1f}x by CPU time, {stat(side, "rtf_wall"):.1f}x by wall '
              f'time; {stat(side, "iters"):.2f} Newton iterations/step, {stat(side, "facts"):.2f} LU '
              f'factorisations/step')
    print(f'  ratio this / ref of the medians: {stat("this", "rtf_cpu") / stat("ref", "rtf_cpu"):.3f} (CPU), '
          f'{stat("this", "rtf_wall") / stat("ref", "rtf_wall"):.3f} (wall); median of the {n} per-pair ratios '
          f'{med(pair_cpu):.3f} (CPU, quartiles {np.percentile(pair_cpu, 25):.3f}-{np.percentile(pair_cpu, 75):.3f}), '
          f'{med(pair_wall):.3f} (wall)')
    print(f'  same steps: max |x_this - x_ref| = {diff:.2e} m after {args.sim_seconds:g} s')


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--sim-seconds', type=float, default=10.0, help='simulated seconds per library run')
    parser.add_argument('--repeats', type=int, default=5, help='library runs (median reported); with '
                        '--compare-ref: worker processes')
    parser.add_argument('--numpy-seconds', type=float, default=0.5, help='simulated seconds per numpy run')
    parser.add_argument('--numpy-repeats', type=int, default=3)
    parser.add_argument('--compare-ref', metavar='REF', help='compare the library path with git revision REF '
                        '(e.g. main), alternating in fresh worker processes, instead')
    parser.add_argument('--ref-tree', metavar='DIR', help='with --compare-ref: a checkout of REF to use '
                        '(default: git archive of REF into ~/.cache/frog_sim/bench_trees/)')
    parser.add_argument('--undamped', action='store_true', help='with --compare-ref: the gait without the '
                        'lumped body damping')
    parser.add_argument('--inner', type=int, default=4, help='with --compare-ref: runs per side in each process')
    parser.add_argument('--worker', metavar='REF_TREE', help=argparse.SUPPRESS)
    parser.add_argument('--first', default='ref', help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        print(json.dumps(measure_pair(Path(args.worker), args.sim_seconds, not args.undamped, args.inner, args.first)))
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
    rtf0, rtf0_cpu = [], []     # the same without the lumped body damping, interleaved
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
                                    reference=integ.reference,
                                    waterline_friction=getattr(integ, 'waterline_friction', (0.0, 0.0)))
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
    print(f'  without the lumped body damping, same run: {med(rtf0_cpu):.1f}x by CPU time, '
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
