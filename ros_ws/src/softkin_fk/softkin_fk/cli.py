"""``softkin``: forward/inverse kinematics, trajectories, calibration and studies from the shell.

Every command writes ``result.json`` (SI units, metres) and PNG pictures rendered offscreen
(matplotlib Agg) into ``--out`` (default ``runs/softkin/<command>``).

Examples
--------
  softkin fk --actuation 1 0.95 0.93                  # finger, cable ratios s_j
  softkin fk --pull-mm 2 3 4                          # finger, cable pulls in mm
  softkin fk --model pneumatic --actuation 1.5 1 1 --enforce
  softkin ik --target-mm 100 54 12.5
  softkin trajectory --curve L                        # Algorithm 3 on the built-in 'L'
  softkin trajectory --csv waypoints.csv --csv-scale 0.001
  softkin calibrate --ratios 3.75 5.68                # Table II analogue
  softkin convergence --resolutions 1 2 3             # tip vs mesh resolution (Fig. 17)
  softkin workspace --ik-every 5                      # finger workspace + built-in curves (PNG)

Your own mesh (gmsh .msh, .vtu, .mesh, ... or TetGen .node/.ele) with a JSON spec sidecar
(units, R_w per region, fixed vertices, actuators, markers; see softkin_fk/core/mesh_spec.py
and examples/finger_mm.json):
  softkin fk --mesh part.msh --spec part.json --actuation 0.9 --out runs/x
  softkin ik --mesh part.msh --spec part.json --target-mm 100 54 12.5 --marker tip
  softkin export --model pneumatic --mesh-out pneu.msh  # a built-in model as mesh + spec
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

MM = 1e-3


class CliError(Exception):
    """A user error: printed without a traceback, exit status 2."""


# --- helpers ----------------------------------------------------------------------------------
def _build_model(args):
    from .core import models
    if getattr(args, 'mesh', None) or getattr(args, 'spec', None):
        return _load_user_mesh(args)
    if args.model in (None, 'finger'):
        return models.build_tendon_finger(resolution=args.resolution)
    if args.model == 'pneumatic':
        return models.build_pneumatic_actuator(resolution=args.resolution)
    if args.model == 'dea':
        return models.build_dea_crawler(resolution=args.resolution)
    raise CliError(f"unknown model {args.model!r}; expected finger, pneumatic or dea")


def _load_user_mesh(args):
    from .core.mesh_spec import MeshSpecError, load_mesh_with_spec
    if not args.mesh:
        raise CliError("--spec needs --mesh (the mesh file it describes)")
    if not args.spec:
        raise CliError(f"--mesh {args.mesh} needs --spec: a JSON file with units, fixed vertices, actuators "
                       "and markers (see examples/finger_mm.json)")
    if args.model not in (None, 'finger'):
        raise CliError("give either --model or --mesh/--spec, not both")
    try:
        return load_mesh_with_spec(args.mesh, args.spec)
    except (MeshSpecError, FileNotFoundError) as exc:
        raise CliError(str(exc))


def _marker(mesh, name):
    if name not in mesh.markers:
        raise CliError(f"the mesh has no marker {name!r}; markers: {sorted(mesh.markers) or 'none'} "
                       "(add it under 'markers' in the spec)")
    return name


def _actuation(mesh, args):
    from .core.models import finger_ratios_from_pull
    n = len(mesh.actuators)
    if getattr(args, 'pull_mm', None) is not None:
        if mesh.info.get('model') != 'tendon_finger':
            raise CliError("--pull-mm applies to the finger only; use --actuation for ratios")
        if len(args.pull_mm) != n:
            raise CliError(f"--pull-mm needs {n} values (one per cable), got {len(args.pull_mm)}")
        return finger_ratios_from_pull(mesh, np.asarray(args.pull_mm) * MM)
    if getattr(args, 'actuation', None) is None:
        return np.ones(n)
    if len(args.actuation) != n:
        raise CliError(f"--actuation needs {n} values ({[a.name for a in mesh.actuators]}), got {len(args.actuation)}")
    return np.asarray(args.actuation, float)


def _outdir(args, name):
    out = args.out or os.path.join('runs', 'softkin', name)
    os.makedirs(out, exist_ok=True)
    return out


def _write_json(path, data):
    def conv(o):
        if isinstance(o, np.ndarray):
            return o.tolist()
        if isinstance(o, (np.floating, np.integer)):
            return o.item()
        if isinstance(o, np.bool_):
            return bool(o)
        raise TypeError(type(o))
    with open(path, 'w') as fh:
        json.dump(data, fh, indent=2, default=conv)


def _plot_mesh(ax, mesh, x, color, alpha=0.6, label=None):
    """Side view (x-y projection, mm) of the boundary triangles."""
    from matplotlib.collections import PolyCollection
    faces = mesh.boundary_faces()
    if len(faces) == 0:  # prism meshes: draw the prisms' top triangles
        faces = np.concatenate([g.elements[:, :3] for g in mesh.groups if g.k == 6])
    polys = x[faces][:, :, :2] / MM
    pc = PolyCollection(polys, facecolor=color, edgecolor='k', linewidth=0.1, alpha=alpha, label=label)
    ax.add_collection(pc)
    ax.autoscale_view()
    ax.set_aspect('equal')
    ax.set_xlabel('x (mm)')
    ax.set_ylabel('y (mm)')


def _figure():
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    return plt


def _fk_json(mesh, res, elapsed):
    return dict(actuation=res.actuation, actuators=[a.name for a in mesh.actuators],
                markers={k: res.positions[v] for k, v in mesh.markers.items()},
                iterations=res.iterations, converged=res.converged, error_estimate_m=res.error_estimate,
                actuator_totals=res.actuator_totals, active=res.active, seconds=elapsed,
                n_vertices=mesh.n_vertices, n_tets=mesh.n_tets, units='m')


# --- commands ---------------------------------------------------------------------------------
def cmd_fk(args):
    from .core.forward import ForwardSolver
    from .core.mesh import write_volume_mesh
    mesh = _build_model(args)
    act = _actuation(mesh, args)
    t0 = time.perf_counter()
    try:
        res = ForwardSolver(mesh).solve(act, tol=args.tol, enforce_constraints=args.enforce)
    except ValueError as exc:
        raise CliError(str(exc))
    elapsed = time.perf_counter() - t0
    out = _outdir(args, 'fk')
    _write_json(os.path.join(out, 'result.json'), _fk_json(mesh, res, elapsed))
    plt = _figure()
    fig, ax = plt.subplots(figsize=(7, 5))
    _plot_mesh(ax, mesh, mesh.vertices, '0.85', 0.4, 'rest')
    _plot_mesh(ax, mesh, res.positions, 'tab:orange', 0.7, 'deformed')
    ax.set_title(f"{mesh.info.get('model')}: actuation {np.round(act, 4).tolist()}")
    fig.savefig(os.path.join(out, 'deformed.png'), dpi=120)
    if args.mesh_out:
        write_volume_mesh(args.mesh_out, mesh, res.positions)
    summary = dict(iterations=res.iterations, converged=res.converged, out=out)
    if 'tip' in mesh.markers:
        summary = dict(tip_m=res.positions[mesh.markers['tip']].tolist(), **summary)
    summary['markers_m'] = {k: res.positions[v].tolist() for k, v in mesh.markers.items()}
    print(json.dumps(summary))
    return 0


def cmd_ik(args):
    from .core.forward import ForwardSolver
    from .core.inverse import solve_ik
    mesh = _build_model(args)
    marker = _marker(mesh, args.marker)
    target = np.asarray(args.target_mm, float) * MM
    fs = ForwardSolver(mesh)
    t0 = time.perf_counter()
    try:
        res = solve_ik(fs, target, markers=(marker,), lam=args.lam_mm * MM, i_max=args.i_max,
                       direction=args.direction, jacobian=args.jacobian)
    except ValueError as exc:
        raise CliError(str(exc))
    elapsed = time.perf_counter() - t0
    out = _outdir(args, 'ik')
    data = dict(target=target, reached=res.reached[0], error_m=res.error, success=res.success,
                out_of_reach=res.out_of_reach, actuation=res.actuation, iterations=res.iterations,
                fk_solves=res.fk_solves, history_m=res.history, seconds=elapsed, units='m')
    _write_json(os.path.join(out, 'result.json'), data)
    plt = _figure()
    fig, ax = plt.subplots(figsize=(7, 5))
    _plot_mesh(ax, mesh, mesh.vertices, '0.85', 0.4)
    _plot_mesh(ax, mesh, res.fk.positions, 'tab:orange', 0.7)
    ax.plot(*(target[:2] / MM), 'k*', ms=12, label='target')
    ax.plot(*(res.reached[0, :2] / MM), 'r^', label='reached')
    ax.legend()
    ax.set_title(f"IK error {res.error / MM:.3f} mm after {res.iterations} iterations")
    fig.savefig(os.path.join(out, 'ik.png'), dpi=120)
    msg = 'reached' if res.success else 'OUT OF REACH: nearest reachable point returned'
    print(json.dumps(dict(status=msg, error_mm=res.error / MM, reached_mm=(res.reached[0] / MM).tolist(),
                          actuation=res.actuation.tolist(), out=out)))
    return 0


def cmd_trajectory(args):
    from tqdm import tqdm

    from .core.forward import ForwardSolver
    from .core.trajectory import CURVES, follow_trajectory, read_waypoints_csv, sample_configuration_space
    mesh = _build_model(args)
    marker = _marker(mesh, args.marker)
    if mesh.info.get('model') != 'tendon_finger' and not args.csv:
        raise CliError("the built-in curves lie in the finger's workspace; give --csv waypoints for other robots")
    if args.csv:
        if not os.path.exists(args.csv):
            raise CliError(f"waypoint file {args.csv!r} not found")
        try:
            P = read_waypoints_csv(args.csv, scale=args.csv_scale)
        except ValueError as exc:
            raise CliError(str(exc))
        name = os.path.splitext(os.path.basename(args.csv))[0]
    else:
        if args.curve not in CURVES:
            raise CliError(f"unknown curve {args.curve!r}; built-in curves: {sorted(CURVES)}")
        P = CURVES[args.curve]() if args.n is None else CURVES[args.curve](args.n)
        name = args.curve
    fs = ForwardSolver(mesh)
    t0 = time.perf_counter()
    n_s = args.samples ** len(mesh.actuators)
    with tqdm(total=n_s, desc='configuration space', disable=args.quiet) as bar:
        cs = sample_configuration_space(fs, args.samples, marker=marker, progress=bar.update)
    t_cs = time.perf_counter() - t0
    t1 = time.perf_counter()
    with tqdm(total=len(P), desc=f'trajectory {name}', disable=args.quiet) as bar:
        tr = follow_trajectory(fs, P, cs, marker=marker, progress=bar.update, lam=args.lam_mm * MM,
                               direction=args.direction, jacobian=args.jacobian)
    t_tr = time.perf_counter() - t1
    out = _outdir(args, f'trajectory_{name}')
    _write_json(os.path.join(out, 'result.json'), dict(
        curve=name, targets=tr.targets, reached=tr.reached, errors_m=tr.errors, reached_flags=tr.reached_flags,
        actuations=tr.actuations, iterations=tr.iterations, fk_solves=tr.fk_solves,
        config_space_seconds=t_cs, trajectory_seconds=t_tr, config_space_points=cs.points,
        config_space_actuations=cs.actuations, units='m'))
    plt = _figure()
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(12, 5))
    ax.plot(cs.points[:, 0] / MM, cs.points[:, 1] / MM, '.', color='0.7', label=f'{n_s} samples')
    ax.plot(tr.targets[:, 0] / MM, tr.targets[:, 1] / MM, 'r.-', ms=4, label='target')
    ax.plot(tr.reached[:, 0] / MM, tr.reached[:, 1] / MM, 'k.-', ms=3, label='achieved (IK + FK)')
    for p, q in zip(tr.targets, tr.reached):
        if np.linalg.norm(p - q) > args.lam_mm * MM:
            ax.plot([p[0] / MM, q[0] / MM], [p[1] / MM, q[1] / MM], '--', color='0.5', lw=0.7)
    ax.set_aspect('equal')
    ax.set_xlabel('x (mm)')
    ax.set_ylabel('y (mm)')
    ax.legend()
    ax.set_title(f"'{name}': {tr.reached_flags.sum()}/{len(P)} waypoints within {args.lam_mm} mm")
    ax2.plot(np.arange(1, len(P) + 1), tr.errors / MM, 'k.-')
    ax2.axhline(args.lam_mm, color='r', ls='--', label='lambda')
    ax2.set_xlabel('waypoint')
    ax2.set_ylabel('position error (mm)')
    ax2.legend()
    fig.tight_layout()
    fig.savefig(os.path.join(out, 'trajectory.png'), dpi=120)
    print(json.dumps(dict(curve=name, waypoints=len(P), reached=int(tr.reached_flags.sum()),
                          max_error_mm=float(tr.errors.max() / MM), config_space_s=t_cs, trajectory_s=t_tr,
                          out=out)))
    return 0


def cmd_calibrate(args):
    from .core.calibration import calibration_table
    for r in args.ratios:
        if not r > 1:
            raise CliError(f"elasticity ratio {r} must exceed 1 (material A is the stiffer one)")
    t0 = time.perf_counter()
    rows = calibration_table(tuple(args.ratios), shape_parameter_a=args.rw_a)
    out = _outdir(args, 'calibrate')
    _write_json(os.path.join(out, 'result.json'), dict(rows=rows, seconds=time.perf_counter() - t0))
    print(f"{'R_m':>6} {'R_w^A':>7} {'R_w^B':>8} {'ratio':>7} {'paper':>7}")
    for r in rows:
        paper = f"{r['paper_ratio']:.2f}" if r['paper_ratio'] else '-'
        print(f"{r['R_m']:6.2f} {r['R_w_A']:7.3f} {r['R_w_B']:8.4f} {r['ratio']:7.2f} {paper:>7}")
    return 0


def cmd_convergence(args):
    from tqdm import tqdm

    from .core.forward import ForwardSolver
    from .core.models import build_tendon_finger, finger_ratios_from_pull
    pulls = np.asarray(args.pull_mm, float) * MM
    rows = []
    for r in tqdm(args.resolutions, desc='resolutions', disable=args.quiet):
        mesh = build_tendon_finger(resolution=r)
        fs = ForwardSolver(mesh)
        t0 = time.perf_counter()
        res = fs.solve(finger_ratios_from_pull(mesh, pulls), tol=1e-8, max_iter=20000)
        dt = time.perf_counter() - t0
        rows.append(dict(resolution=r, n_vertices=mesh.n_vertices, n_tets=mesh.n_tets,
                         tip=res.positions[mesh.markers['tip']], iterations=res.iterations,
                         seconds=dt, seconds_per_iteration=dt / max(res.iterations, 1), converged=res.converged))
    ref = rows[-1]['tip']
    for row in rows:
        row['tip_difference_to_finest_m'] = float(np.linalg.norm(row['tip'] - ref))
    out = _outdir(args, 'convergence')
    _write_json(os.path.join(out, 'result.json'), dict(pull_m=pulls, rows=rows))
    plt = _figure()
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4))
    nv = [r['n_vertices'] for r in rows]
    a1.plot(nv, [r['tip_difference_to_finest_m'] / MM for r in rows], 'ko-')
    a1.set_xlabel('vertices')
    a1.set_ylabel('tip distance to finest mesh (mm)')
    a2.plot(nv, [r['seconds_per_iteration'] * 1e3 for r in rows], 'bo-')
    a2.set_xlabel('vertices')
    a2.set_ylabel('time per iteration (ms)')
    fig.tight_layout()
    fig.savefig(os.path.join(out, 'convergence.png'), dpi=120)
    for row in rows:
        print(f"res {row['resolution']}: {row['n_vertices']} vertices, {row['n_tets']} tets, tip "
              f"{np.round(row['tip'] / MM, 3).tolist()} mm, diff {row['tip_difference_to_finest_m'] / MM:.3f} mm, "
              f"{row['iterations']} its, {row['seconds']:.1f} s")
    return 0


def cmd_export(args):
    from .core.mesh_spec import MeshSpecError, export_mesh_with_spec
    mesh = _build_model(args)
    d = os.path.dirname(os.path.abspath(args.mesh_out))
    os.makedirs(d, exist_ok=True)
    try:
        export_mesh_with_spec(mesh, args.mesh_out, args.spec_out, units=args.units)
    except MeshSpecError as exc:
        raise CliError(str(exc))
    spec = args.spec_out or os.path.splitext(args.mesh_out)[0] + '.json'
    print(json.dumps(dict(mesh=args.mesh_out, spec=spec, n_vertices=mesh.n_vertices,
                          groups=[g.name for g in mesh.groups], actuators=[a.name for a in mesh.actuators])))
    return 0


def cmd_workspace(args):
    from tqdm import tqdm

    from .core.curves import CURVES, workspace_region
    from .core.forward import ForwardSolver
    from .core.inverse import solve_ik
    from .core.trajectory import sample_configuration_space
    mesh = _build_model(args)
    if mesh.info.get('model') != 'tendon_finger':
        raise CliError("the workspace picture is for the finger (planar, bending in x-y)")
    for c in args.curves:
        if c not in CURVES:
            raise CliError(f"unknown curve {c!r}; built-in curves: {sorted(CURVES)}")
    if args.samples < 2:
        raise CliError(f"--samples {args.samples} must be >= 2")
    fs = ForwardSolver(mesh)
    t0 = time.perf_counter()
    n_s = args.samples ** len(mesh.actuators)
    with tqdm(total=n_s, desc='configuration space', disable=args.quiet) as bar:
        cs = sample_configuration_space(fs, args.samples, fk_tol=args.fk_tol, progress=bar.update)
    t_cs = time.perf_counter() - t0
    region = workspace_region(cs.actuations, cs.points)
    r_in, c_in = region.largest_inscribed_circle()
    lam = args.lam_mm * MM
    curves = {}
    for name in args.curves:
        P = CURVES[name]()
        m = region.margin(P)
        row = dict(n=len(P), min_margin_m=float(m.min()), margins_m=m, waypoints=P)
        if args.ik_every > 0:
            idx = np.arange(0, len(P), args.ik_every)
            errs, its, reached, starts = [], [], [], []
            for i in tqdm(idx, desc=f'IK {name}', disable=args.quiet):
                # independent solves (no warm start from the previous waypoint) from the nearest
                # samples' actuations; FK is re-solved at IK's own tolerance.
                # A further start only when IK stalls in a local minimum at the actuation bounds.
                order = np.argsort(np.linalg.norm(cs.points - P[i], axis=1))[:max(args.ik_starts, 1)]
                best = None
                for n_try, k in enumerate(order, 1):
                    r = solve_ik(fs, P[i], initial=cs.actuations[k], lam=lam, direction='gauss-newton')
                    if best is None or r.error < best.error:
                        best = r
                    if r.error <= lam:
                        break
                errs.append(best.error)
                its.append(best.iterations)
                reached.append(best.reached[0])
                starts.append(n_try)
            errs = np.array(errs)
            row.update(ik_indices=idx, ik_errors_m=errs, ik_iterations=np.array(its), ik_reached=np.array(reached),
                       ik_starts=np.array(starts), ik_max_error_m=float(errs.max()),
                       ik_all_within_lambda=bool(np.all(errs <= lam)))
        curves[name] = row
    out = _outdir(args, 'workspace')
    _write_json(os.path.join(out, 'result.json'), dict(
        resolution=mesh.info.get('resolution'), samples_per_axis=args.samples, fk_tol_m=args.fk_tol,
        config_space_seconds=t_cs,
        config_space_points=cs.points, config_space_actuations=cs.actuations, inscribed_radius_m=r_in,
        inscribed_centre_m=c_in, lam_m=lam, curves=curves, units='m'))
    plt = _figure()
    fig, ax = plt.subplots(figsize=(7, 7))
    ax.contourf(region.xs / MM, region.ys / MM, region.distance.T / MM, levels=[1e-9, 1, 2, 3, 4, 5, 6, 8],
                cmap='Greens', alpha=0.6)
    ax.contour(region.xs / MM, region.ys / MM, region.inside.T.astype(float), levels=[0.5], colors='g',
               linewidths=0.8)
    ax.plot(cs.points[:, 0] / MM, cs.points[:, 1] / MM, '.', color='0.4', ms=2, label=f'{n_s} FK samples')
    for (name, row), col in zip(curves.items(), ('r', 'b', 'm', 'c')):
        P = row['waypoints']
        ax.plot(P[:, 0] / MM, P[:, 1] / MM, '.-', color=col, ms=3, lw=0.8,
                label=f"'{name}' (N = {row['n']}), margin >= {row['min_margin_m'] / MM:.1f} mm")
        if 'ik_reached' in row:
            R = row['ik_reached']
            ax.plot(R[:, 0] / MM, R[:, 1] / MM, 'kx', ms=5,
                    label=f"IK every {args.ik_every}th: max error {row['ik_max_error_m'] / MM:.3f} mm")
    ax.set_aspect('equal')
    ax.set_xlabel('x (mm)')
    ax.set_ylabel('y (mm)')
    ax.legend(fontsize=7, loc='lower left')
    ax.set_title(f"finger tip workspace (resolution {mesh.info.get('resolution')}; shading: distance to the "
                 "boundary, 1 mm steps)", fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(out, 'curves_workspace.png'), dpi=130)
    summary = dict(out=out, config_space_s=t_cs, inscribed_radius_mm=r_in / MM)
    for name, row in curves.items():
        summary[name] = dict(min_margin_mm=row['min_margin_m'] / MM)
        if 'ik_errors_m' in row:
            summary[name].update(ik_waypoints=len(row['ik_errors_m']), ik_max_error_mm=row['ik_max_error_m'] / MM,
                                 ik_errors_mm=np.round(row['ik_errors_m'] / MM, 3).tolist(),
                                 ik_starts=row['ik_starts'].tolist(), ik_all_within_lambda=row['ik_all_within_lambda'])
    print(json.dumps(summary))
    return 0


def build_parser():
    p = argparse.ArgumentParser(prog='softkin', description=__doc__.split('\n')[0],
                                epilog=__doc__.split('Examples\n--------\n')[1],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest='command', required=True)

    def common(sp, name, user_mesh=True):
        sp.add_argument('--model', default=None, help='finger (default), pneumatic or dea')
        if user_mesh:
            sp.add_argument('--mesh', default=None,
                            help='your own volume mesh instead of --model: .msh, .vtu, .vtk, .mesh, ... '
                                 '(meshio) or TetGen .node/.ele; needs --spec')
            sp.add_argument('--spec', default=None,
                            help='JSON spec of --mesh: units, R_w regions, fixed vertices, actuators, markers '
                                 '(see examples/finger_mm.json)')
        sp.add_argument('--resolution', type=int, default=None,
                        help='mesh resolution of the model (finger: cells per 5 mm; default from models.py)')
        sp.add_argument('--out', default=None, help=f'output folder (default runs/softkin/{name})')
        sp.add_argument('--quiet', action='store_true', help='no progress bars')

    raw = argparse.RawDescriptionHelpFormatter
    sp = sub.add_parser('fk', help='forward kinematics of an actuation', formatter_class=raw,
                        epilog='examples:\n  softkin fk --pull-mm 2 3 4\n'
                               '  softkin fk --model pneumatic --actuation 1.5 1 1\n'
                               '  softkin fk --mesh part.msh --spec part.json --actuation 0.9 --out runs/x\n'
                               '  softkin fk --mesh body.node --spec body.json --actuation 2.0   # TetGen')
    common(sp, 'fk')
    sp.add_argument('--actuation', type=float, nargs='+',
                    help='actuation ratios (cable s, pneumatic alpha, DEA lambda)')
    sp.add_argument('--pull-mm', type=float, nargs='+', help='finger: cable pull lengths (mm)')
    sp.add_argument('--enforce', action='store_true', help='meet eq. 6-8 exactly (secant correction)')
    sp.add_argument('--tol', type=float, default=1e-8, help='FK tolerance (m), default 1e-8')
    sp.add_argument('--mesh-out', default=None, help='also write the deformed mesh (meshio format by extension)')
    sp.set_defaults(func=cmd_fk)

    sp = sub.add_parser('ik', help='inverse kinematics for a tip target (Algorithm 2)', formatter_class=raw,
                        epilog='examples:\n  softkin ik --target-mm 100 54 12.5\n'
                               '  softkin ik --mesh part.msh --spec part.json --target-mm 100 54 12.5 --marker tip')
    common(sp, 'ik')
    sp.add_argument('--marker', default='tip', help="tracked marker (default 'tip')")
    sp.add_argument('--target-mm', type=float, nargs=3, required=True, help='target tip position x y z (mm)')
    sp.add_argument('--lam-mm', type=float, default=0.2, help='stop when the tip error <= this (mm), default 0.2')
    sp.add_argument('--i-max', type=int, default=30, help='iteration limit, default 30')
    sp.add_argument('--direction', default='gauss-newton', choices=['gradient', 'gauss-newton'],
                    help="search direction: the paper's gradient or Gauss-Newton (default)")
    sp.add_argument('--jacobian', default='central', choices=['central', 'implicit'],
                    help="IK gradient: the paper's central differences (default) or the implicit-function "
                         "sensitivity (same gradient to ~1e-7, one solve with the FK factorisation; 3-4x faster)")
    sp.set_defaults(func=cmd_ik)

    sp = sub.add_parser('trajectory', help='trajectory following (Algorithm 3)',
                        epilog='examples: softkin trajectory --curve flame; softkin trajectory --csv pts.csv;\n'
                               '  softkin trajectory --curve L --jacobian implicit')
    common(sp, 'trajectory')
    sp.add_argument('--marker', default='tip', help="tracked marker (default 'tip')")
    sp.add_argument('--curve', default='L', help="built-in curve: 'L' (N=55) or 'flame' (N=85)")
    sp.add_argument('--n', type=int, default=None, help='number of waypoints (default: the curve\'s N)')
    sp.add_argument('--csv', default=None, help='waypoints file: x,y[,z] per line')
    sp.add_argument('--csv-scale', type=float, default=1e-3, help='CSV units to metres (default 0.001: mm)')
    sp.add_argument('--samples', type=int, default=5, help='configuration samples per cable (default 5: 125)')
    sp.add_argument('--lam-mm', type=float, default=0.2, help='IK threshold (mm)')
    sp.add_argument('--direction', default='gauss-newton', choices=['gradient', 'gauss-newton'])
    sp.add_argument('--jacobian', default='central', choices=['central', 'implicit'],
                    help="IK gradient: the paper's central differences (default) or the implicit-function "
                         "sensitivity (same gradient to ~1e-7, one solve with the FK factorisation; 3-4x faster)")
    sp.set_defaults(func=cmd_trajectory)

    sp = sub.add_parser('workspace', help="finger tip workspace with the built-in curves (PNG) and an IK check",
                        formatter_class=raw,
                        epilog='examples:\n  softkin workspace                 # 7^3 samples, curves_workspace.png\n'
                               '  softkin workspace --ik-every 5    # + IK on every 5th waypoint of each curve')
    common(sp, 'workspace', user_mesh=False)
    sp.add_argument('--samples', type=int, default=7, help='samples per cable (default 7: 343 FK solves)')
    sp.add_argument('--curves', nargs='+', default=['L', 'flame'], help="curves to overlay (default: L flame)")
    sp.add_argument('--ik-every', type=int, default=0,
                    help='run IK (from the nearest sample) on every k-th waypoint of each curve; 0 = no IK')
    sp.add_argument('--fk-tol', type=float, default=1e-9,
                    help='FK tolerance (m) of the samples, default 1e-9: they draw the workspace boundary')
    sp.add_argument('--ik-starts', type=int, default=3,
                    help='IK starts per checked waypoint: the nearest samples, tried in turn (default 3)')
    sp.add_argument('--lam-mm', type=float, default=0.2, help='IK threshold (mm)')
    sp.set_defaults(func=cmd_workspace)

    sp = sub.add_parser('export', help='write a built-in model as a mesh file + JSON spec (a template)',
                        formatter_class=raw,
                        epilog='examples:\n'
                               '  softkin export --model finger --resolution 1 --mesh-out finger.msh --units mm\n'
                               '  softkin export --model pneumatic --mesh-out pneu.node   # TetGen + region attributes')
    sp.add_argument('--model', default=None, help='finger (default), pneumatic or dea')
    sp.add_argument('--resolution', type=int, default=None, help='mesh resolution of the model')
    sp.add_argument('--mesh-out', required=True,
                    help='mesh file: .msh (gmsh 2.2), .vtu, .mesh, ... or .node (TetGen, tetrahedra only)')
    sp.add_argument('--spec-out', default=None, help='spec file (default: mesh path with .json)')
    sp.add_argument('--units', default='m', help='units of the written coordinates and spec lengths (default m)')
    sp.set_defaults(func=cmd_export)

    sp = sub.add_parser('calibrate', help='R_w calibration of two-material bars (eq. 16, Table II)')
    sp.add_argument('--ratios', type=float, nargs='+', default=[3.75, 5.68], help='elasticity ratios R_m')
    sp.add_argument('--rw-a', type=float, default=1.0, help='R_w of the stiffer material A (fixed)')
    sp.add_argument('--out', default=None)
    sp.set_defaults(func=cmd_calibrate)

    sp = sub.add_parser('convergence', help='finger tip position vs mesh resolution (Fig. 17 analogue)')
    sp.add_argument('--resolutions', type=int, nargs='+', default=[1, 2, 3, 4])
    sp.add_argument('--pull-mm', type=float, nargs=3, default=[3.0, 3.0, 3.0], help='cable pulls (mm)')
    sp.add_argument('--out', default=None)
    sp.add_argument('--quiet', action='store_true')
    sp.set_defaults(func=cmd_convergence)
    return p


def main(argv=None):
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, 'resolution', 'x') is None:
        from .core.models import DEFAULT_FINGER_RESOLUTION
        args.resolution = DEFAULT_FINGER_RESOLUTION if args.model in (None, 'finger') else 1
    try:
        return args.func(args)
    except CliError as exc:
        print(f"softkin {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == '__main__':
    sys.exit(main())
