"""softkin_fk benchmarks (issue 6): FK iteration, 240-degree bending, IK trajectories, config space.

Sections (run all, or name some):

* ``iteration`` -- one local/global iteration (local step + right side + pre-factorised solve)
  on a ~52k-tetrahedron bar. Target <= 30 ms; paper: 25 fps (40 ms) on a 4-core Xeon (C++).
* ``bend240`` -- bending a ~49k-tetrahedron single-cable actuator (models.BENDER: 22 slots) to
  >= 240 degrees, one solve from rest. Target <= 10 s; paper: 23.2 s.
* ``ik`` -- at the default finger resolution: the 125-sample configuration space (target
  <= 4 s; paper 8.3 s) and trajectory following of 'L' (N = 55, target <= 10 s; paper 38 s) and
  'flame' (N = 85, target <= 15 s; paper 46 s).

Every time is also measured with the plain numpy implementation (batched numpy SVD local
step, ``numpy.add.at`` assembly, same scipy factorisation; ``ForwardSolver(use_numba=False)``)
in the same run -- on a shorter workload where the full one would take too long, scaled per
unit of work, as stated in the output. Medians over repetitions are quoted.

    ./dev run python bench/softkin_benchmarks.py [iteration] [bend240] [ik] [--reps N] [--json FILE]
"""
from __future__ import annotations

import argparse
import json
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


def line(name, ours, numpy_time, note=''):
    paper, target = PAPER[name], TARGET[name]
    ok = 'PASS' if ours <= target else 'MISS'
    print(f"{name:13s} ours {ours:9.3f} s | target {target:6.2f} s {ok} | paper {paper:6.2f} s "
          f"(ours/paper {ours / paper:6.2f}) | numpy {numpy_time:9.3f} s (numpy/ours {numpy_time / ours:5.1f}x) {note}")
    return dict(name=name, seconds=ours, target=target, paper=paper, numpy_seconds=numpy_time,
                ratio_to_paper=ours / paper, numpy_over_ours=numpy_time / ours, note=note)


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
        times = []
        for _ in range(n):
            t0 = time.perf_counter()
            fs.local_step(x)
            fs.global_step(fp)
            times.append(time.perf_counter() - t0)
        out[use_numba] = statistics.median(times)
    return [line('iteration', out[True], out[False], f'({mesh.n_tets} tets, {mesh.n_vertices} vertices, median)')]


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
    ForwardSolver(mesh).solve([0.999], max_iter=2)  # compile the kernels outside the timing
    times, res = [], None
    for _ in range(max(1, reps // 10)):
        fs = ForwardSolver(mesh)
        t0 = time.perf_counter()
        res = fs.solve([s], tol=1e-6, max_iter=20000)
        times.append(time.perf_counter() - t0)
    ang = bend_angle(mesh, res.positions)
    # numpy: same solver with the numpy local step, timed on 30 iterations, scaled to the count
    fsn = ForwardSolver(mesh, use_numba=False)
    t0 = time.perf_counter()
    fsn.solve([s], tol=0.0, max_iter=30)
    per_it = (time.perf_counter() - t0) / 30
    note = (f"({mesh.n_tets} tets, {res.iterations} iterations, converged {res.converged}, bending angle "
            f"{ang:.1f} deg; numpy = 30 iterations scaled to {res.iterations})")
    return [line('bend240', statistics.median(times), per_it * res.iterations, note)]


def bench_ik(reps, resolution, curves=('L', 'flame')):
    mesh = build_tendon_finger(resolution)
    out = []
    fs = ForwardSolver(mesh)
    fs.solve([0.99, 0.99, 0.99])  # compile
    t0 = time.perf_counter()
    cs = sample_configuration_space(fs, 5)
    t_cs = time.perf_counter() - t0
    fsn = ForwardSolver(mesh, use_numba=False)
    t0 = time.perf_counter()
    sample_configuration_space(fsn, 2)  # 8 samples
    t_cs_np = (time.perf_counter() - t0) * 125 / 8
    out.append(line('config_space', t_cs, t_cs_np, f'(125 samples, res {resolution}; numpy: 8 samples x 125/8)'))
    for name, curve in (('L', curve_L()), ('flame', curve_flame())):
        if name not in curves:
            continue
        t0 = time.perf_counter()
        tr = follow_trajectory(fs, curve, cs, direction='gauss-newton')
        t = time.perf_counter() - t0
        t0 = time.perf_counter()
        follow_trajectory(fsn, curve[:5], cs, direction='gauss-newton')
        t_np = (time.perf_counter() - t0) * len(curve) / 5
        note = (f"({len(curve)} waypoints, {tr.reached_flags.sum()} within 0.2 mm, median error "
                f"{np.median(tr.errors) * 1e3:.3f} mm, max {tr.errors.max() * 1e3:.2f} mm, "
                f"{tr.fk_solves.sum()} FK solves; numpy: first 5 waypoints scaled)")
        out.append(line(name, t, t_np, note))
    return out


def main():
    p = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    p.add_argument('sections', nargs='*', default=['iteration', 'bend240', 'ik'])
    p.add_argument('--reps', type=int, default=20)
    p.add_argument('--resolution', type=int, default=DEFAULT_FINGER_RESOLUTION)
    p.add_argument('--curves', nargs='+', default=['L', 'flame'], help="trajectories of the ik section")
    p.add_argument('--json', default=None, help='also write the table as JSON')
    a = p.parse_args()
    rows = []
    for sec in a.sections:
        if sec == 'iteration':
            rows += bench_iteration(a.reps)
        elif sec == 'bend240':
            rows += bench_bend240(a.reps)
        elif sec == 'ik':
            rows += bench_ik(a.reps, a.resolution, a.curves)
        else:
            p.error(f"unknown section {sec!r}; expected iteration, bend240 or ik")
    if a.json:
        with open(a.json, 'w') as fh:
            json.dump(rows, fh, indent=2, default=float)


if __name__ == '__main__':
    main()
