"""softkin_fk benchmarks: FK iteration, 240-degree bending, IK trajectories, config space.

Sections (run all, or name some):

* ``iteration`` -- one local/global iteration (local step + right side + pre-factorised solve)
  on a ~52k-tetrahedron bar. Target <= 30 ms; paper: 25 fps (40 ms) on a 4-core Xeon (C++).
* ``bend240`` -- bending a ~49k-tetrahedron single-cable actuator (models.BENDER: 22 slots) to
  >= 240 degrees, one solve from rest with the default solver (projected Newton; its Hessian
  pattern and symbolic factorisation are built inside the timed region). Target <= 10 s;
  paper: 23.2 s.
* ``ik`` -- at the default finger resolution: the 125-sample configuration space (target
  <= 4 s; paper 8.3 s) and trajectory following of 'L' (N = 55, target <= 10 s; paper 38 s) and
  'flame' (N = 85, target <= 15 s; paper 46 s), each with the implicit (IFT) Jacobian and with
  the paper's central differences (``--jacobians``).

The numpy baseline is the plain numpy implementation measured in the same run: batched numpy
SVD local step, ``numpy.add.at`` assembly, same global factorisation, and the solver the
package used before Newton (L-BFGS preconditioned by the global matrix, i.e. local/global
steps; ``ForwardSolver(use_numba=False)``), with central-difference IK. Where its full
workload would take too long it runs a shorter one, scaled per unit of work, as stated in the
output. Times are medians over repetitions of wall-clock time; the CPU time of the process
(``time.process_time``, all threads) is printed too, since on a shared 2-core machine wall
time includes waiting for the CPU (the load average is printed at the start).

    ./dev bench softkin_benchmarks [iteration] [bend240] [ik] [--reps N] [--json FILE]
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import time

import numpy as np

from softkin_fk.core.forward import ForwardSolver
from softkin_fk.core.mesh import ElementGroup, SoftMesh
from softkin_fk.core.meshing import voxel_tets
from softkin_fk.core.models import BENDER, DEFAULT_FINGER_RESOLUTION, build_tendon_finger
from softkin_fk.core.trajectory import curve_flame, curve_L, follow_trajectory, sample_configuration_space

PAPER = dict(iteration=0.040, bend240=23.2, config_space=8.3, L=38.0, flame=46.0)
TARGET = dict(iteration=0.030, bend240=10.0, config_space=4.0, L=10.0, flame=15.0)


def line(name, ours, numpy_time, note='', cpu=None, label=None):
    """One table row: figure, target, paper, ratio to paper, ratio to the numpy baseline."""
    paper, target = PAPER[name], TARGET[name]
    ok = 'MET ' if ours <= target else 'MISSED'
    label = label or name
    cpu_s = f" cpu {cpu:8.3f} s |" if cpu is not None else ''
    print(f"{label:18s} ours {ours:9.3f} s |{cpu_s} target {target:6.2f} s {ok} | paper {paper:6.2f} s "
          f"(ours/paper {ours / paper:5.2f}) | numpy {numpy_time:9.3f} s (numpy/ours {numpy_time / ours:6.1f}x) "
          f"{note}", flush=True)
    return dict(name=label, seconds=ours, cpu_seconds=cpu, target=target, met=ours <= target, paper=paper,
                numpy_seconds=numpy_time, ratio_to_paper=ours / paper, numpy_over_ours=numpy_time / ours, note=note)


def timed(f):
    t0, c0 = time.perf_counter(), time.process_time()
    out = f()
    return time.perf_counter() - t0, time.process_time() - c0, out


def bench_iteration(reps):
    v, t, _, g = voxel_tets(np.ones((72, 12, 10), bool), 2.5e-3)
    mesh = SoftMesh(v, [ElementGroup('body', 'body', t, shape_parameter=0.8)], fixed=g[0].ravel())
    rng = np.random.default_rng(0)
    x = v + 1e-4 * rng.standard_normal(v.shape)
    fp = v[mesh.fixed]
    out = {}
    for use_numba, n in ((True, reps), (False, max(3, reps // 5))):
        fs = ForwardSolver(mesh, use_numba=use_numba)
        fs.local_step(x)
        fs.global_step(fp)
        walls, cpus = [], []
        for _ in range(n):
            w, c, _ = timed(lambda: (fs.local_step(x), fs.global_step(fp)))
            walls.append(w)
            cpus.append(c)
        out[use_numba] = (statistics.median(walls), statistics.median(cpus), fs.global_solver.backend)
    return [line('iteration', out[True][0], out[False][0],
                 f'({mesh.n_tets} tets, {mesh.n_vertices} vertices, R_w 0.8, global back end {out[True][2]}, '
                 f'median of {reps})', cpu=out[True][1])]


def bend_angle(mesh, x):
    """Bending angle (deg) of the actuator: the tangent angle of its bottom centre line
    (y = 0, z = mid-width) at the tip, unwrapped along the length (so 240 deg is 240, not -120)."""
    v = mesh.vertices
    zmid = 0.5 * (v[:, 2].min() + v[:, 2].max())
    line_ = np.flatnonzero(np.isclose(v[:, 1], 0.0) & np.isclose(v[:, 2], zmid))
    line_ = line_[np.argsort(v[line_, 0])]
    d = np.diff(x[line_], axis=0)
    ang = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
    return float(np.degrees(ang[-1]))


def bench_bend240(reps):
    mesh = build_tendon_finger(3, geometry=BENDER, width_cells=6, max_slot_closure=0.97)
    s = mesh.actuators[0].bounds[0]
    warm = ForwardSolver(mesh)  # compile the kernels outside the timing
    warm.solve([0.999], max_iter=2)
    warm.solve([0.999], max_iter=2, method='lbfgs')
    walls, cpus, res = [], [], None
    for _ in range(max(1, reps // 10)):
        fs = ForwardSolver(mesh)
        w, c, res = timed(lambda: fs.solve([s], tol=1e-6, max_iter=20000))
        walls.append(w)
        cpus.append(c)
    ang = bend_angle(mesh, res.positions)
    # the same solve by the previous default (L-BFGS + local/global, numba), once: its iteration
    # count scales the numpy baseline's per-iteration time
    w_lb, _, r_lb = timed(lambda: ForwardSolver(mesh).solve([s], tol=1e-6, max_iter=20000, method='lbfgs'))
    dev = float(np.abs(r_lb.positions - res.positions).max())
    fsn = ForwardSolver(mesh, use_numba=False)
    w30, _, _ = timed(lambda: fsn.solve([s], tol=0.0, max_iter=30, method='lbfgs'))
    numpy_t = w30 / 30 * r_lb.iterations
    note = (f"({mesh.n_tets} tets, Newton {res.iterations} iterations, converged {res.converged}, bending angle "
            f"{ang:.1f} deg; numba L-BFGS {w_lb:.1f} s / {r_lb.iterations} it, shapes agree to {dev * 1e3:.3f} mm; "
            f"numpy = 30 L-BFGS iterations scaled to {r_lb.iterations})")
    return [line('bend240', statistics.median(walls), numpy_t, note, cpu=statistics.median(cpus))]


def bench_ik(reps, resolution, curves=('L', 'flame'), jacobians=('implicit', 'central')):
    mesh = build_tendon_finger(resolution)
    out = []
    fs = ForwardSolver(mesh)
    fs.sensitivity(fs.solve([0.99, 0.99, 0.99]))  # compile
    fsn = ForwardSolver(mesh, use_numba=False)
    cs = None
    walls, cpus = [], []
    for _ in range(max(1, reps // 10)):
        w, c, cs = timed(lambda: sample_configuration_space(fs, 5))
        walls.append(w)
        cpus.append(c)
    w_np, _, _ = timed(lambda: sample_configuration_space(fsn, 2))  # 8 samples
    t_cs_np = w_np * 125 / 8
    its = sum(r.iterations for r in cs.results)
    # accuracy of the samples: re-solve every 25th tightly from its own shape
    dev = max(float(np.abs(fs.solve(cs.actuations[k], x0=cs.results[k].positions, tol=1e-10,
                                    active0=cs.results[k].active).positions
                           - cs.results[k].positions).max()) for k in range(0, len(cs.results), 25))
    out.append(line('config_space', statistics.median(walls), t_cs_np,
                    f'(125 samples, res {resolution}, {its} Newton iterations, FK tol 0.1 mm, samples within '
                    f'{dev * 1e3:.1e} mm of 1e-10 m solves; numpy: 8 samples x 125/8)', cpu=statistics.median(cpus)))
    for name, curve in (('L', curve_L()), ('flame', curve_flame())):
        if name not in curves:
            continue
        w_np, _, _ = timed(lambda: follow_trajectory(fsn, curve[:5], cs, direction='gauss-newton'))
        t_np = w_np * len(curve) / 5
        for jac in jacobians:
            w, c, tr = timed(lambda: follow_trajectory(fs, curve, cs, direction='gauss-newton', jacobian=jac))
            note = (f"({len(curve)} waypoints, {tr.reached_flags.sum()} within 0.2 mm, median error "
                    f"{np.median(tr.errors) * 1e3:.3f} mm, max {tr.errors.max() * 1e3:.2f} mm, "
                    f"{tr.iterations.sum()} IK iterations, {tr.fk_solves.sum()} FK solves; "
                    f"numpy: central, first 5 waypoints scaled)")
            out.append(line(name, w, t_np, note, cpu=c, label=f'{name} ({jac})'))
    return out


def main():
    p = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    p.add_argument('sections', nargs='*', default=['iteration', 'bend240', 'ik'])
    p.add_argument('--reps', type=int, default=20)
    p.add_argument('--resolution', type=int, default=DEFAULT_FINGER_RESOLUTION)
    p.add_argument('--curves', nargs='+', default=['L', 'flame'], help="trajectories of the ik section")
    p.add_argument('--jacobians', nargs='+', default=['implicit', 'central'],
                   help="IK Jacobians of the ik section: implicit (IFT) and/or central (the paper)")
    p.add_argument('--json', default=None, help='also write the table as JSON')
    a = p.parse_args()
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs", flush=True)
    rows = []
    for sec in a.sections:
        if sec == 'iteration':
            rows += bench_iteration(a.reps)
        elif sec == 'bend240':
            rows += bench_bend240(a.reps)
        elif sec == 'ik':
            rows += bench_ik(a.reps, a.resolution, a.curves, a.jacobians)
        else:
            p.error(f"unknown section {sec!r}; expected iteration, bend240 or ik")
    missed = [r['name'] for r in rows if not r['met']]
    print('targets missed: ' + (', '.join(missed) if missed else 'none'))
    if a.json:
        with open(a.json, 'w') as fh:
            json.dump(rows, fh, indent=2, default=float)


if __name__ == '__main__':
    main()
