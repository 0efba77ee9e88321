"""The robot's own primitive sequences replayed open loop over N periods.

Path following lives on several periods: a kick whose turn carries into the next
periods adds up. For every reconstructed decision ``k`` of a hardware run
(:mod:`frog_sim.core.hardware_runs`) with ``N`` further whole decisions logged after it,
the simulator starts from the measured body velocity at ``d_k`` (eq. 13, limbs at
rest), fires the logged primitives ``k .. k+N-1`` one period apart (each ``latency``
after its decision, as ``frog-sim fidelity``), and the pose after ``N`` periods is
compared with the robot's, both in the start body frame:

* **heading ratio**: the least-squares slope of simulated on real heading change over
  all windows, ``sum(s r) / sum(r^2)`` (1 = as much turn as the robot, with signs);
* **RMS heading error** and **RMS position error** at the end of the window.

Per run and pooled, for N = 1 .. ``n_max``. A window of N periods is the first N
periods of the longest window that starts at ``d_k`` (the later primitives cannot act
earlier), so one simulation per decision serves every N.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from .core import hardware_runs as hr
from .core.schedules import ActivationSchedule

#: Longest replay [periods].
DEFAULT_N_MAX = 5


@dataclass
class ReplayWindow:
    """One decision and the logged primitives after it (SI; poses in the start body frame).

    ``real`` and ``sim`` hold one ``(dx, dy, dheading)`` per period end (index j = after
    j + 1 periods).
    """

    run: str
    index: int
    time: float
    period: float
    primitives: list
    forward: float
    lateral: float
    yaw_rate: float
    real: list
    sim: list = field(default_factory=list)
    curve: dict = field(default_factory=dict)

    @property
    def periods(self) -> int:
        return len(self.primitives)


def real_windows(logs: dict, tag_offset: float, n_max: int = DEFAULT_N_MAX, curves: bool = False) -> list:
    """:class:`ReplayWindow` for every decision of ``logs`` (name -> HardwareLog).

    A window runs over the longest stretch (at most ``n_max``) of consecutive decisions
    whose poses are all inside the log.
    """
    out = []
    for name, log in logs.items():
        fit = hr.fit_decision_times(log)
        trs = hr.measure_transitions(log, fit, tag_offset=tag_offset)
        by_index = {tr.index: tr for tr in trs}
        for tr in trs:
            seq = [tr]
            while len(seq) < n_max and (tr.index + len(seq)) in by_index:
                seq.append(by_index[tr.index + len(seq)])
            p0 = hr.local_pose(log, tr.time, tag_offset)
            real = [hr.relative_pose(p0, hr.local_pose(log, tr.time + (j + 1) * fit.period, tag_offset))
                    for j in range(len(seq))]
            w = ReplayWindow(run=name, index=tr.index, time=tr.time, period=fit.period,
                             primitives=[s.primitive for s in seq], forward=tr.forward, lateral=tr.lateral,
                             yaw_rate=tr.yaw_rate, real=[list(r) for r in real])
            if curves:
                tau, dh, _ = hr.heading_curve(log, tr.time, len(seq) * fit.period, dt=0.05, tag_offset=tag_offset)
                w.curve = {'tau': tau.tolist(), 'real': dh.tolist()}
            out.append(w)
    return out


def simulate_window(sim, w: ReplayWindow, latency: float, curve: bool = False) -> list:
    """The window's primitives from its start velocity; fills and returns ``w.sim``."""
    sim.reset()
    prims = [p for p in w.primitives]
    sched = ActivationSchedule.primitive_sequence(prims, period=w.period, pulse=sim.params.pulse_duration,
                                                  start=latency)
    sim.set_schedule(sched)
    sim.set_velocity(w.forward, w.lateral, w.yaw_rate)
    traj = sim.run(w.periods * w.period + 0.01, record_interval=0.01)
    h0 = traj.heading[0]
    c, s = np.cos(h0), np.sin(h0)
    out = []
    for j in range(w.periods):
        t = (j + 1) * w.period
        heading = float(np.interp(t, traj.time, traj.heading))
        ex = float(np.interp(t, traj.time, traj.com[:, 0]) - traj.com[0, 0])
        ey = float(np.interp(t, traj.time, traj.com[:, 1]) - traj.com[0, 1])
        out.append([c * ex + s * ey, -s * ex + c * ey, heading - h0])
    w.sim = out
    if curve and w.curve:
        w.curve['sim'] = np.interp(w.curve['tau'], traj.time, traj.heading - h0).tolist()
    return out


def window_metrics(windows, n_max: int = DEFAULT_N_MAX) -> dict:
    """Per N: heading ratio (LSQ slope), mean |heading| ratio, RMS heading / position error, n."""
    out = {}
    for n in range(1, n_max + 1):
        rows = [(w.real[n - 1], w.sim[n - 1]) for w in windows if w.periods >= n and len(w.sim) >= n]
        if not rows:
            continue
        r = np.array([a for a, _ in rows])
        s = np.array([b for _, b in rows])
        den = float(np.sum(r[:, 2] ** 2))
        out[n] = {'n': len(rows),
                  'heading_ratio': float(np.sum(s[:, 2] * r[:, 2]) / den) if den > 0 else float('nan'),
                  'abs_heading_ratio': float(np.mean(np.abs(s[:, 2])) / np.mean(np.abs(r[:, 2]))),
                  'rms_heading_error': float(np.sqrt(np.mean((s[:, 2] - r[:, 2]) ** 2))),
                  'rms_position_error': float(np.sqrt(np.mean(np.sum((s[:, :2] - r[:, :2]) ** 2, axis=1)))),
                  'real_abs_heading': float(np.mean(np.abs(r[:, 2])))}
    return out


def replay_report(sim, windows, latency: float, n_max: int = DEFAULT_N_MAX, progress=None) -> dict:
    """Simulate every window; metrics pooled and per run (JSON-ready)."""
    for w in windows:
        simulate_window(sim, w, latency, curve=bool(w.curve))
        if progress:
            progress()
    runs = sorted({w.run for w in windows})
    groups = sorted({run_group(w.run) for w in windows})
    return {'n_max': n_max, 'latency': latency,
            'pooled': window_metrics(windows, n_max),
            'groups': {g: window_metrics([w for w in windows if run_group(w.run) == g], n_max) for g in groups},
            'per_run': {run: window_metrics([w for w in windows if w.run == run], n_max) for run in runs},
            'windows': [asdict(w) for w in windows]}


def run_group(run: str) -> str:
    """The group a run is scored in: ``'ellipse'`` (many turning periods in a row) or ``'line/sine'``."""
    return 'ellipse' if run.startswith('ellipse') else 'line/sine'


def format_replay_table(rep: dict) -> str:
    """Pooled and per-run table (deg, mm)."""
    deg = np.degrees(1.0)
    lines = ['N-period open-loop replays of the robot\'s own primitive sequences (start body frame):',
             f'{"":>8} {"N":>2} {"n":>4} | {"heading ratio":>13} {"|dh| ratio":>10} | {"RMS dh err":>10} '
             f'{"RMS pos err":>11} | {"real |dh|":>9}']

    def rows(label, m):
        for n, r in sorted(m.items(), key=lambda kv: int(kv[0])):
            lines.append(f'{label:>8} {int(n):2d} {r["n"]:4d} | {r["heading_ratio"]:13.2f} '
                         f'{r["abs_heading_ratio"]:10.2f} | {deg * r["rms_heading_error"]:7.1f} deg '
                         f'{1e3 * r["rms_position_error"]:8.1f} mm | {deg * r["real_abs_heading"]:5.1f} deg')
    rows('pooled', rep['pooled'])
    for group, m in rep.get('groups', {}).items():
        rows(group, m)
    for run, m in rep['per_run'].items():
        rows(run, m)
    return '\n'.join(lines)


def plot_replays(rep: dict, out, n_windows: int = 6) -> list:
    """PNGs: error vs N (pooled and per run); real vs simulated heading of a few windows."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    from pathlib import Path
    out = Path(out)
    deg = np.degrees(1.0)
    files = []
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.3))
    for label, m, style in [('pooled', rep['pooled'], 'k-o')] + [
            (run, mm, '--.') for run, mm in rep['per_run'].items()]:
        ns = sorted(int(n) for n in m)
        lw = 2.2 if label == 'pooled' else 0.9
        axes[0].plot(ns, [m[n]['heading_ratio'] for n in ns], style, lw=lw, label=label)
        axes[1].plot(ns, [deg * m[n]['rms_heading_error'] for n in ns], style, lw=lw, label=label)
        axes[2].plot(ns, [1e3 * m[n]['rms_position_error'] for n in ns], style, lw=lw, label=label)
    axes[0].axhspan(0.85, 1.15, color='g', alpha=0.12, label='target 0.85-1.15')
    axes[0].axhline(1.0, color='k', lw=0.6)
    axes[0].set_ylabel('heading change, sim / real (LSQ slope)')
    axes[1].set_ylabel('RMS heading error at the window end [deg]')
    axes[2].set_ylabel('RMS position error at the window end [mm]')
    for ax in axes:
        ax.set_xlabel('periods replayed N')
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7, ncol=2)
    fig.suptitle('the robot\'s logged primitives replayed open loop from the measured state at each decision')
    fig.tight_layout()
    files.append(out / 'replay_error_vs_n.png')
    fig.savefig(files[-1], dpi=110)
    plt.close(fig)

    wins = [w for w in rep['windows'] if w.get('curve', {}).get('sim') is not None]
    wins = sorted(wins, key=lambda w: -abs(w['real'][-1][2]))[:n_windows]
    if wins:
        cols = min(3, len(wins))
        rows_ = int(np.ceil(len(wins) / cols))
        fig, axes = plt.subplots(rows_, cols, figsize=(5 * cols, 3.4 * rows_), squeeze=False)
        for ax, w in zip(axes.ravel(), wins):
            tau = np.array(w['curve']['tau'])
            ax.plot(tau, deg * np.array(w['curve']['real'], dtype=float), 'k', label='robot')
            ax.plot(tau, deg * np.array(w['curve']['sim']), 'C1', label='simulator')
            for j in range(1, w['periods'] if 'periods' in w else len(w['primitives'])):
                ax.axvline(j * w['period'], color='0.7', lw=0.6)
            for j, p in enumerate(w['primitives']):
                ax.text((j + 0.5) * w['period'], 0.95, p, transform=ax.get_xaxis_transform(), ha='center')
            ax.set_title(f'{w["run"]} decision {w["index"]}', fontsize=9)
            ax.set_xlabel('time after the decision [s]')
            ax.set_ylabel('heading change [deg]')
            ax.grid(alpha=0.3)
        axes.ravel()[0].legend(fontsize=8)
        for ax in axes.ravel()[len(wins):]:
            ax.axis('off')
        fig.tight_layout()
        files.append(out / 'replay_windows.png')
        fig.savefig(files[-1], dpi=110)
        plt.close(fig)
    return files


def heading_wander(sim, windows, primitive: str = 'B', draws: int = 4, latency: float = 0.10) -> tuple[float, float]:
    """Mean |heading change| over one period of ``primitive`` decisions: (real, simulated) [rad].

    The simulated decisions fire the primitive at once (so that the simulator's kick
    variability, :meth:`~frog_sim.core.simulation.FrogSimulation.set_kick_variability`,
    applies), ``draws`` times each. For B, a symmetric kick, the robot's wander measures how
    much its left and right kicks differ from one firing to the next.
    """
    real, simulated = [], []
    for w in windows:
        if w.primitives[0] != primitive:
            continue
        real.append(abs(w.real[0][2]))
        for _ in range(draws):
            sim.reset()
            sim.set_velocity(w.forward, w.lateral, w.yaw_rate)
            sim.run(latency, record_interval=0.05)
            sim.execute_primitive(primitive)
            sim.run(w.period - latency, record_interval=0.05)
            simulated.append(abs(sim.rigid_body_state().heading))
    if not real:
        raise ValueError(f'no {primitive} decision among the windows')
    return float(np.mean(real)), float(np.mean(simulated))
