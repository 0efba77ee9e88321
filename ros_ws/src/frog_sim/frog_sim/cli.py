"""``frog-sim``: run the frog simulator from the command line.

Sub-commands
------------
gait        swim a periodic gait, write CSV + NPZ (+ metadata) and a PNG
primitives  execute a sequence of motion primitives (A-I or 0-8), same outputs
params      print the parameter table with sources
fit         print the eq. 9 fit of every measured curvature profile (RMS errors)
validate    simulated vs measured steady speed, 10 % EGaIn, phase 0.5 (RMS error)
convergence time-step and edge-length convergence of the 10-cycle displacement
fidelity    the simulator vs the real robot: transitions, kick response, coasting, speeds
disturbance identify the twin's yaw disturbance and kick spread from the hardware runs
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

EXAMPLES = """examples:
  frog-sim gait --frequency 1.0 --phase 0.5 --duration 10 --out runs/gait_1hz
  frog-sim gait --egain 30 --frequency 1.3 --duration 8 --forward 0.02 --yaw-rate 0.2
  frog-sim primitives --sequence A,B,C,I --period 1.5 --out runs/prims
  frog-sim primitives --sequence 0,3,3,5 --forward 0.02 --lateral -0.01
  frog-sim params
  frog-sim fit
  FROG_DATA_DIR=../shared/data/frog frog-sim fit --write-package-data
  frog-sim validate --out runs/validation
  frog-sim convergence --out runs/convergence
  frog-sim fidelity --out runs/fidelity                 # table, PNGs, fidelity.json (incl. N-period replays)
  frog-sim fidelity --no-speeds --set body_drag_normal=1.2 --set limb_root_angle_deg=-60
  frog-sim disturbance --out runs/disturbance        # the twin's yaw disturbance (about 10 min)
"""


class CliError(Exception):
    """Bad user input (printed without a traceback, exit status 2)."""


def _positive(name):
    def parse(text):
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f'{name} must be a number, got {text!r}') from None
        if not np.isfinite(value) or value <= 0:
            raise argparse.ArgumentTypeError(f'{name} must be > 0, got {text!r}')
        return value
    return parse


def _add_common(p):
    p.add_argument('--egain', type=float, default=10.0,
                   help='EGaIn volume %% of the limbs (measured: 0-50 in steps of 10; default 10)')
    p.add_argument('--dt', type=_positive('--dt'), default=None, help='time step [s] (default: the library default)')
    p.add_argument('--duration', type=_positive('--duration'), default=None, help='simulated time [s]')
    p.add_argument('--forward', type=float, default=0.0, help='initial forward COM velocity [m/s] (eq. 13)')
    p.add_argument('--lateral', type=float, default=0.0, help='initial lateral (left) COM velocity [m/s]')
    p.add_argument('--yaw-rate', type=float, default=0.0, help='initial yaw rate [rad/s]')
    p.add_argument('--record-interval', type=_positive('--record-interval'), default=0.01,
                   help='sampling interval of the output [s] (default 0.01)')
    p.add_argument('--snapshots', type=int, default=6, help='rod snapshots drawn in the PNG (default 6)')
    p.add_argument('--out', type=Path, default=None,
                   help='output folder (default runs/frog_sim/<command>_<UTC time>)')
    p.add_argument('--no-plot', action='store_true', help='skip the PNG')
    p.add_argument('--quiet', action='store_true', help='no progress bar')


def build_parser() -> argparse.ArgumentParser:
    """Argument parser of ``frog-sim``."""
    parser = argparse.ArgumentParser(
        prog='frog-sim', description='2D discrete-elastic-rods simulator of the frog robot (paper seed 000).',
        epilog=EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest='command', metavar='COMMAND')
    g = sub.add_parser('gait', help='swim a periodic gait', epilog=EXAMPLES,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    g.add_argument('--frequency', type=_positive('--frequency'), default=1.0,
                   help='actuation frequency [Hz]; must be measured for the EGaIn fraction (default 1.0)')
    g.add_argument('--phase', type=float, default=0.5, help='rear delay as a fraction of the cycle, 0-1 (default 0.5)')
    _add_common(g)
    pr = sub.add_parser('primitives', help='execute motion primitives', epilog=EXAMPLES,
                        formatter_class=argparse.RawDescriptionHelpFormatter)
    pr.add_argument('--sequence', required=True,
                    help='comma-separated primitives, names A-I or ids 0-8 (A=1100 ... I=0000, bits FR,FL,BL,BR)')
    pr.add_argument('--period', type=_positive('--period'), default=1.5,
                    help='one primitive per period [s] (default 1.5)')
    pr.add_argument('--pulse', type=_positive('--pulse'), default=0.08,
                    help='pulse length [s]: rear delay (default 0.08)')
    _add_common(pr)
    sub.add_parser('params', help='print the parameter table with sources')
    ft = sub.add_parser('fit', help='print the eq. 9 fit of every measured profile; regenerate the shipped fit',
                        epilog=EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)
    ft.add_argument('--refit', action='store_true',
                    help='refit from the measurements (FROG_DATA_DIR or shared/data/frog) instead of '
                         'printing the shipped fit')
    ft.add_argument('--write-package-data', action='store_true',
                    help='refit from the measurements and write the result as the shipped package data '
                         '(frog_sim/data/actuation_fit.json in the source tree)')
    ft.add_argument('--output', type=Path, default=None,
                    help='with --write-package-data: write here instead of the package data file')
    v = sub.add_parser('validate', help='speed vs calibration runs (10 %% EGaIn, phase 0.5)')
    v.add_argument('--dt', type=_positive('--dt'), default=None)
    v.add_argument('--out', type=Path, default=None)
    c = sub.add_parser('convergence', help='dt and dl convergence of the 10-cycle displacement')
    c.add_argument('--out', type=Path, default=None)
    fi = sub.add_parser('fidelity', help='simulator vs real robot (hardware runs, speeds): table, PNGs, JSON',
                        epilog=EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)
    fi.add_argument('--out', type=Path, default=None, help='output folder (default runs/frog_sim/fidelity_<time>)')
    fi.add_argument('--no-speeds', action='store_true', help='skip the speed comparisons (~1 min)')
    fi.add_argument('--latency', type=float, default=None,
                    help='decision -> firing delay of the simulated primitives [s] (default 0.10)')
    fi.add_argument('--tag-offset-deg', type=float, default=None,
                    help='robot heading = tag theta + offset (default: estimated from B on the line runs)')
    fi.add_argument('--set', action='append', default=[], metavar='NAME=VALUE',
                    help='override a model parameter (repeatable), e.g. body_drag_normal=1.2')
    fi.add_argument('--dt', type=_positive('--dt'), default=None)
    fi.add_argument('--replay-periods', type=int, default=5, metavar='N',
                    help='replay the logged primitive sequences open loop for 1..N periods (0: skip; default 5)')
    fi.add_argument('--quiet', action='store_true', help='no progress bar')
    di = sub.add_parser('disturbance', help="identify the twin's yaw disturbance (sd, tau) and per-firing kick "
                        "spread from the hardware runs' residual heading per period", epilog=EXAMPLES,
                        formatter_class=argparse.RawDescriptionHelpFormatter)
    di.add_argument('--out', type=Path, default=None, help='output folder (default runs/frog_sim/disturbance_<time>)')
    di.add_argument('--seeds', type=int, default=8, help='random draws per run and grid point (default 8)')
    di.add_argument('--taus', type=str, default=None, help='time constants to try [s], comma-separated')
    di.add_argument('--kicks', type=str, default=None, help='per-firing kick spreads to try, comma-separated')
    di.add_argument('--quiet', action='store_true', help='no progress bar')
    return parser


def _out_dir(args, command) -> Path:
    out = args.out or Path('runs') / 'frog_sim' / f'{command}_{time.strftime("%Y%m%dT%H%M%SZ", time.gmtime())}'
    out.mkdir(parents=True, exist_ok=True)
    return out


def _make_sim(args):
    from .core.model_parameters import FrogParameters
    from .core.simulation import DEFAULT_TIME_STEP, FrogSimulation
    try:
        params = FrogParameters().replace(egain_vol_pct=args.egain)
        return FrogSimulation(params, time_step=args.dt or DEFAULT_TIME_STEP)
    except ValueError as exc:
        raise CliError(str(exc)) from None


def write_outputs(traj, out: Path, title: str, snapshots: int, plot: bool, network=None) -> list[Path]:
    """Write ``trajectory.csv``, ``trajectory.npz``, ``metadata.json`` (and ``trajectory.png``)."""
    meta = dict(traj.metadata)
    meta['created_utc'] = time.strftime('%Y-%m-%dT%H:%M:%SZ', time.gmtime())
    meta['command'] = ' '.join(sys.argv)
    files = []
    csv_path = out / 'trajectory.csv'
    cols = np.column_stack([traj.time, traj.com, traj.heading, traj.com_velocity, traj.body_velocity,
                            traj.yaw_rate])
    header = ('t_s,com_x_m,com_y_m,heading_rad,com_vx_m_s,com_vy_m_s,forward_velocity_m_s,'
              'lateral_velocity_m_s,yaw_rate_rad_s')
    with open(csv_path, 'w') as fh:
        fh.write('# frog-sim trajectory (SI units, world frame tank, eq. 10-12); metadata in metadata.json\n')
        fh.write(f'# code_version: {meta.get("code_version")}, time_step_s: {meta.get("time_step_s")}\n')
        np.savetxt(fh, cols, delimiter=',', header=header, comments='', fmt='%.9g')
    files.append(csv_path)
    npz_path = out / 'trajectory.npz'
    np.savez_compressed(npz_path, time=traj.time, positions=traj.positions, com=traj.com,
                        heading=traj.heading, com_velocity=traj.com_velocity,
                        body_velocity=traj.body_velocity, yaw_rate=traj.yaw_rate,
                        edges=np.zeros((0, 2), dtype=int) if network is None else network.edges,
                        metadata=json.dumps(meta))
    files.append(npz_path)
    meta_path = out / 'metadata.json'
    meta_path.write_text(json.dumps(meta, indent=1, default=float))
    files.append(meta_path)
    if plot:
        files.append(plot_trajectory(traj, out / 'trajectory.png', title, snapshots, network))
    return files


def plot_trajectory(traj, path: Path, title: str, snapshots: int = 6, network=None) -> Path:
    """PNG with the COM path and rod snapshots (as paper Fig. 3c-d)."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(8, 5), dpi=120)
    n_snap = max(snapshots, 2)
    times = np.linspace(traj.time[0], traj.time[-1], n_snap)
    gait = traj.metadata.get('gait')
    if gait:   # spread the snapshots over the stroke phase too (limbs at different states)
        period = 1.0 / gait['frequency_hz']
        times = np.minimum(times + (np.arange(n_snap) % 4) * 0.06 * period, traj.time[-1])
    idx = np.unique(np.searchsorted(traj.time, times).clip(0, len(traj.time) - 1))
    cmap = plt.get_cmap('viridis')
    for k, i in enumerate(idx):
        pos = traj.positions[i] * 1e3
        color = cmap(k / max(len(idx) - 1, 1))
        if network is not None:
            seg = pos[network.edges]
            for s in seg:
                ax.plot(s[:, 0], s[:, 1], '-', color=color, lw=1.2)
        else:
            ax.plot(pos[:, 0], pos[:, 1], '.', color=color, ms=2)
        ax.annotate(f'{traj.time[i]:.1f} s', xy=traj.com[i] * 1e3, xytext=(0, -60),
                    textcoords='offset points', ha='center', fontsize=7, color=color)
    ax.plot(traj.com[:, 0] * 1e3, traj.com[:, 1] * 1e3, 'r-', lw=1.5, label='centre of mass')
    ax.set_aspect('equal')
    ax.set_xlabel('x [mm]')
    ax.set_ylabel('y [mm]')
    ax.set_title(title, fontsize=9)
    ax.legend(loc='upper left', fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def _run_sim(args, sim, title):
    from .core.integrator import ConvergenceError
    sim.set_velocity(args.forward, args.lateral, args.yaw_rate)
    try:
        traj = sim.run(args.duration, record_interval=args.record_interval, progress=not args.quiet)
    except ConvergenceError as exc:
        raise CliError(f'simulation failed: {exc}') from None
    out = _out_dir(args, args.command)
    files = write_outputs(traj, out, title, args.snapshots, not args.no_plot, sim.model.network)
    st = sim.rigid_body_state()
    print(f'{title}\nfinal COM ({st.com[0]:.4f}, {st.com[1]:.4f}) m, heading {np.degrees(st.heading):.2f} deg, '
          f'body velocity ({st.body_velocity[0]:.4f}, {st.body_velocity[1]:.4f}) m/s')
    for f in files:
        print(f'wrote {f}')


def cmd_gait(args):
    if not 0.0 <= args.phase < 1.0:
        raise CliError(f'--phase {args.phase} must be in [0, 1)')
    sim = _make_sim(args)
    try:
        sim.set_gait(args.frequency, args.phase)
    except ValueError as exc:
        raise CliError(str(exc)) from None
    args.duration = args.duration or 10.0 / args.frequency
    _run_sim(args, sim, f'gait {args.frequency:g} Hz, phase {args.phase:g}, EGaIn {args.egain:g} %')


def cmd_primitives(args):
    from frog_common.primitives import primitive_name

    from .core.schedules import ActivationSchedule
    items = [s.strip() for s in args.sequence.split(',') if s.strip()]
    if not items:
        raise CliError('--sequence is empty; give e.g. A,B,C or 0,1,2')
    try:
        names = [primitive_name(int(s) if s.isdigit() else s) for s in items]
    except ValueError as exc:
        raise CliError(str(exc)) from None
    sim = _make_sim(args)
    sched = ActivationSchedule.primitive_sequence(names, period=args.period, pulse=args.pulse)
    sim.set_schedule(sched)
    args.duration = args.duration or len(names) * args.period
    _run_sim(args, sim, f'primitives {"".join(names)} every {args.period:g} s, EGaIn {args.egain:g} %')


def cmd_params(args):
    from .core.model_parameters import parameter_table
    print(f'{"parameter":32s} {"value":>12s} {"unit":8s} source')
    for name, value, unit, source in parameter_table():
        val = f'{value:.6g}' if isinstance(value, float) else str(value)
        print(f'{name:32s} {val:>12s} {unit:8s} {source}')


def cmd_fit(args):
    from .core.actuation import DATA_FILE_NAME, ActuationLibrary, find_data_dir, package_fit_path
    if args.write_package_data or args.refit:
        lib = ActuationLibrary.fit_file(find_data_dir() / DATA_FILE_NAME, use_cache=not args.write_package_data)
    else:
        lib = ActuationLibrary.load()
    src = lib.source
    print(f'eq. 9 fit from {src.get("loaded_from")} (data sha256 {str(src.get("data_sha256"))[:16]}, '
          f'fit version {src.get("fit_version")}, code {src.get("code_version")}, '
          f'checked against the measurements: {src.get("verified")})')
    print(f'{"EGaIn %":>7s} {"f Hz":>5s} {"t0 s":>6s} {"kappa_relaxed":>13s} {"kappa_min":>9s} {"RMS 1/m":>8s}')
    for p in lib.profiles.values():
        t = np.linspace(0, p.cycle_time, 400)
        print(f'{p.egain_vol_pct:7.0f} {p.frequency_hz:5.1f} {p.switch_time:6.3f} {p.relaxed_curvature:13.1f} '
              f'{p.curvature(t).min():9.1f} {p.rms_error:8.2f}')
    if args.write_package_data:
        # the source tree's file (resolve: a symlink install links the package to the sources)
        target = args.output or Path(__file__).resolve().parent.joinpath('data', 'actuation_fit.json')
        lib.write_json(target)
        print(f'wrote {target}')
        if args.output is None and package_fit_path().resolve() != target.resolve():
            print(f'note: the installed package reads {package_fit_path()}; rebuild to install the new file')


def cmd_validate(args):
    from .core.simulation import DEFAULT_TIME_STEP
    from .studies import speed_validation
    out = _out_dir(args, 'validate')
    print('f [Hz]  measured long  measured 3 cycles  simulated   [mm/s]')

    def show(r):
        print(f'{r.frequency_hz:6.1f} {r.measured_long * 1e3:14.1f} {r.measured_three_cycles * 1e3:18.1f} '
              f'{r.simulated * 1e3:10.1f}', flush=True)
    rows, rms = speed_validation(time_step=args.dt or DEFAULT_TIME_STEP, progress=show)
    print(f'RMS error (simulated - mean measured): {rms * 1e3:.1f} mm/s')
    with open(out / 'speed_vs_frequency.csv', 'w') as fh:
        fh.write('frequency_hz,measured_long_m_s,measured_three_cycles_m_s,simulated_m_s\n')
        for r in rows:
            fh.write(f'{r.frequency_hz},{r.measured_long:.6g},{r.measured_three_cycles:.6g},{r.simulated:.6g}\n')
        fh.write(f'# rms_error_m_s,{rms:.6g}\n')
    print(f'wrote {out / "speed_vs_frequency.csv"}')


def cmd_convergence(args):
    from .studies import convergence_study
    out = _out_dir(args, 'convergence')

    def show(kind, row):
        print(f'{kind} = {row[0] * 1e3:7.3f} mm|ms  10-cycle displacement {row[1] * 1e3:9.4f} mm  '
              f'change {row[2] * 1e3:9.4f} mm', flush=True)
    res = convergence_study(progress=show)
    (out / 'convergence.json').write_text(json.dumps(res, indent=1, default=float))
    print(f'wrote {out / "convergence.json"}')


def parse_overrides(items) -> dict:
    """``['name=value', ...]`` -> ``{name: value}`` for :class:`FrogParameters` (typed by its defaults)."""
    from .core.model_parameters import FrogParameters
    defaults = FrogParameters().as_dict()
    out = {}
    for item in items:
        name, sep, text = item.partition('=')
        name = name.strip()
        if not sep:
            raise CliError(f'--set {item!r}: expected NAME=VALUE')
        if name not in defaults:
            import difflib
            close = difflib.get_close_matches(name, list(defaults), n=1)
            raise CliError(f'--set {name}: not a model parameter' + (f' (did you mean {close[0]}?)' if close else ''))
        kind = type(defaults[name])
        try:
            out[name] = kind(text) if kind is not int else int(float(text))
        except ValueError:
            raise CliError(f'--set {item!r}: {name} needs a {kind.__name__}') from None
    return out


def cmd_fidelity(args):
    from .core.model_parameters import FrogParameters
    from .core.simulation import DEFAULT_TIME_STEP
    from .fidelity import FidelityConfig, fidelity_report, format_table, plot_report
    try:
        params = FrogParameters().replace(**parse_overrides(args.set))
    except ValueError as exc:
        raise CliError(str(exc)) from None
    config = FidelityConfig(time_step=args.dt or DEFAULT_TIME_STEP, speeds=not args.no_speeds,
                            tag_offset_deg=args.tag_offset_deg, replay_periods=args.replay_periods)
    if not 0 <= args.replay_periods <= 10:
        raise CliError(f'--replay-periods {args.replay_periods} must be in 0-10')
    if args.latency is not None:
        if not 0.0 <= args.latency < 1.0:
            raise CliError(f'--latency {args.latency} must be in [0, 1) s')
        config.latency = args.latency
    out = _out_dir(args, 'fidelity')
    bar = None
    if not args.quiet:
        from tqdm import tqdm
        bar = tqdm(desc='fidelity simulations', unit='sim')
    t0, c0 = time.perf_counter(), time.process_time()
    rep = fidelity_report(params, config, progress=(bar.update if bar is not None else None))
    if bar is not None:
        bar.close()
    table = format_table(rep)
    print(table)
    (out / 'fidelity.txt').write_text(table + '\n')
    (out / 'fidelity.json').write_text(rep.to_json())
    files = plot_report(rep, out)
    print(f'{time.perf_counter() - t0:.0f} s wall, {time.process_time() - c0:.0f} s CPU')
    for f in [out / 'fidelity.txt', out / 'fidelity.json', *files]:
        print(f'wrote {f}')


def _float_list(text, name, low, high):
    try:
        values = tuple(float(v) for v in text.split(','))
    except ValueError:
        raise CliError(f'{name} {text!r}: expected comma-separated numbers') from None
    if not values or not all(np.isfinite(v) and low <= v <= high for v in values):
        raise CliError(f'{name} {text!r}: every value must be in [{low:g}, {high:g}]')
    return values


def cmd_disturbance(args):
    from . import disturbance_fit as df
    from . import multi_period as mp
    from .core import hardware_runs as hr
    from .core.actuation import find_data_file
    from .core.simulation import FrogSimulation
    taus = _float_list(args.taus, '--taus', 0.05, 100.0) if args.taus else df.DEFAULT_TAUS
    kicks = _float_list(args.kicks, '--kicks', 0.0, 0.5) if args.kicks else df.DEFAULT_KICK_SDS
    if not 1 <= args.seeds <= 100:
        raise CliError(f'--seeds {args.seeds} must be in 1-100')
    folder = find_data_file('hardware_runs/line1.csv').parent
    logs = hr.read_hardware_runs(folder)
    offset, _, _ = hr.estimate_tag_offset([logs['line1'], logs['line2']])
    windows = mp.real_windows(logs, offset, 1)
    out = _out_dir(args, 'disturbance')
    bar = None
    if not args.quiet:
        from tqdm import tqdm
        bar = tqdm(total=(len([k for k in kicks if k > 0]) + len(taus) + 1) * len(hr.HARDWARE_RUNS) * args.seeds,
                   desc='disturbance runs', unit='run')
    t0, c0 = time.perf_counter(), time.process_time()
    fit = df.identify(FrogSimulation(), windows, taus=taus, kick_sds=kicks, seeds=args.seeds,
                      progress=(bar.update if bar is not None else None))
    if bar is not None:
        bar.close()
    text = df.format_fit(fit)
    print(text)
    (out / 'disturbance.txt').write_text(text + '\n')
    (out / 'disturbance.json').write_text(json.dumps(fit.to_dict(), indent=1) + '\n')
    df.plot_fit(fit, out / 'disturbance.png')
    print(f'{time.perf_counter() - t0:.0f} s wall, {time.process_time() - c0:.0f} s CPU')
    for f in ('disturbance.txt', 'disturbance.json', 'disturbance.png'):
        print(f'wrote {out / f}')


def main(argv=None) -> int:
    """Entry point of ``frog-sim``; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 2
    handlers = {'gait': cmd_gait, 'primitives': cmd_primitives, 'params': cmd_params, 'fit': cmd_fit,
                'validate': cmd_validate, 'convergence': cmd_convergence, 'fidelity': cmd_fidelity,
                'disturbance': cmd_disturbance}
    try:
        handlers[args.command](args)
    except CliError as exc:
        print(f'frog-sim: error: {exc}', file=sys.stderr)
        return 2
    except FileNotFoundError as exc:
        print(f'frog-sim: error: {exc}', file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print('frog-sim: interrupted', file=sys.stderr)
        return 130
    return 0


if __name__ == '__main__':
    sys.exit(main())
