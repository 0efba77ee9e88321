"""Identify the yaw disturbance of the twin from the hardware runs (``frog-sim disturbance``).

Target: the robot's residual heading change per period, ``e_k = real_k - sim_k`` (each
decision replayed for one period from its measured state by the deterministic model,
:mod:`frog_sim.multi_period`), and its autocovariance over consecutive decisions of a run,
``C(j) = mean(e_k e_{k+j})``, pooled over the runs (no mean removed: a bias that holds
for a whole run is part of the disturbance).

Model: the twin's two variations, the Ornstein-Uhlenbeck yaw torque of
:mod:`frog_sim.core.yaw_disturbance` (``sd``, ``tau``) and the per-firing kick spread
(``kick_sd``, :meth:`FrogSimulation.set_kick_variability`, white from period to period).
The simulator swims each run's logged primitive sequence open loop from its first
decision's state, ``seeds`` times, beside the same run without variation; the per-period
heading changes' differences give ``C_sim(j)``. The heading response is linear in the
small torque, so its part scales with ``sd^2``: for each (``kick_sd``, ``tau``) of a grid,
``sd`` matches ``C(0)``, and the point whose autocorrelations ``C(1)/C(0)``, ``C(2)/C(0)``
are nearest the robot's is taken. Lags 3 and 4 are not fitted: they are the check.

The residuals hold the model's own error as well, so the identified disturbance is an
upper bound of the tank's (the twin errs on the side of a harder world).
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from . import multi_period as mp

#: Reference torque of the grid runs [N m] (rescaled by the fit).
REFERENCE_SD = 2.0e-5
DEFAULT_TAUS = (0.75, 1.0, 1.25, 1.5, 1.75, 2.0)
DEFAULT_KICK_SDS = (0.0, 0.05, 0.1)
MAX_LAG = 4
MAX_RESCALES = 3


def autocovariance(series: list, max_lag: int = MAX_LAG) -> tuple[np.ndarray, np.ndarray]:
    """Pooled ``C(j)`` of several runs' series (no mean removed) and the number of pairs per lag."""
    c = np.zeros(max_lag + 1)
    n = np.zeros(max_lag + 1, dtype=int)
    for s in series:
        s = np.asarray(s, dtype=float)
        for j in range(min(max_lag + 1, len(s))):
            c[j] += float(np.sum(s[j:] * s[:len(s) - j]))
            n[j] += len(s) - j
    return np.where(n > 0, c / np.maximum(n, 1), np.nan), n


def run_sequences(windows) -> dict:
    """Per run: (period, the first decision's window, every decision's primitive in order),
    the runs' consecutive decisions only (a gap ends the sequence)."""
    out = {}
    for w in sorted(windows, key=lambda w: (w.run, w.index)):
        seq = out.get(w.run)
        if seq is None:
            out[w.run] = (w.period, w, [w.primitives[0]], w.index)
        elif w.index == seq[3] + 1:
            out[w.run] = (seq[0], seq[1], seq[2] + [w.primitives[0]], w.index)
    return {k: v[:3] for k, v in out.items()}


def real_residuals(sim, windows, latency: float) -> dict:
    """Per run: the residual heading change per period [rad] of its decisions (one-period windows)."""
    out = {}
    for w in sorted(windows, key=lambda w: (w.run, w.index)):
        s = mp.simulate_window(sim, w, latency)
        out.setdefault(w.run, []).append(w.real[0][2] - s[0][2])
    return out


def _headings(sim, start, period: float, primitives, latency: float) -> np.ndarray:
    """Heading at each decision time of the sequence (each primitive fired ``latency`` after its
    decision by :meth:`execute_primitive`, so that the kick variability applies)."""
    sim.reset()
    sim.set_velocity(start.forward, start.lateral, start.yaw_rate)
    out = [sim.rigid_body_state().heading]
    for p in primitives:
        sim.run(latency, record_interval=latency)
        sim.execute_primitive(p)
        sim.run(period - latency, record_interval=period - latency)
        out.append(sim.rigid_body_state().heading)
    return np.unwrap(np.array(out))


def simulated_residuals(sim, sequences: dict, sd: float, tau: float, seeds: int, latency: float,
                        kick_sd: float = 0.0, seed: int = 0, progress=None) -> list:
    """Series of per-period heading-change differences (varied - deterministic) [rad], one per run
    and seed: the yaw disturbance (``sd`` [N m], ``tau`` [s]) and the per-firing kick spread ``kick_sd``."""
    out = []
    for i, (run, (period, start, prims)) in enumerate(sorted(sequences.items())):
        sim.set_yaw_disturbance(0.0, tau)
        sim.set_kick_variability(0.0)
        base = np.diff(_headings(sim, start, period, prims, latency))
        for k in range(seeds):
            sim.set_yaw_disturbance(sd, tau, seed=seed + 1000 * k + i)
            sim.set_kick_variability(kick_sd, seed=seed + 1000 * k + i + 500)
            out.append(np.diff(_headings(sim, start, period, prims, latency)) - base)
            if progress is not None:
                progress(1)
    sim.set_yaw_disturbance(0.0, tau)
    sim.set_kick_variability(0.0)
    return out


def implied_rms(c, n: int) -> float:
    """RMS heading error after ``n`` periods that residuals with autocovariance ``c`` alone give:
    ``sqrt(sum_{i, j < n} C(|i - j|))`` (the error of a sum of ``n`` consecutive residuals)."""
    return float(math.sqrt(sum(c[abs(i - j)] for i in range(n) for j in range(n))))


def held_out_predictability(windows, resid: dict) -> float:
    """How much of the residual a model of the state could remove: the leave-one-run-out R^2 of a
    linear regression of the residual on the primitive, the previous primitive (one-hot) and the
    measured body velocity (forward, lateral, yaw rate) at the decision (1 - SSE / sum e^2)."""
    rows, y, runs = [], [], []
    for run in sorted(resid):
        ws = sorted((w for w in windows if w.run == run), key=lambda w: w.index)
        prev = ''
        for w, e in zip(ws, resid[run]):
            p = w.primitives[0]
            rows.append([float(p == c) for c in 'ABCDEFGH'] + [float(prev == c) for c in 'ABCDEFGH']
                        + [w.forward, w.lateral, w.yaw_rate])
            y.append(e)
            runs.append(run)
            prev = p
    x, y, runs = np.array(rows), np.array(y), np.array(runs)
    x = x[:, x.std(axis=0) > 0]
    pred = np.zeros_like(y)
    for run in set(runs.tolist()):
        m = runs == run
        coef, *_ = np.linalg.lstsq(x[~m], y[~m], rcond=None)
        pred[m] = x[m] @ coef
    return float(1.0 - np.sum((y - pred) ** 2) / np.sum(y ** 2))


@dataclass
class DisturbanceFit:
    """The identified disturbance and every number behind it (angles in rad, C in rad^2)."""

    sd: float
    tau: float
    kick_sd: float
    real_c: list
    real_n: list
    fitted_c: list
    b_wander_real: float
    b_wander_fitted: float
    held_out_r2: float
    grid: list = field(default_factory=list)     # per (kick_sd, tau): sd, C(0..MAX_LAG) predicted, score
    seeds: int = 0
    latency: float = 0.1

    def to_dict(self) -> dict:
        return asdict(self)


def identify(sim, windows, taus=DEFAULT_TAUS, kick_sds=DEFAULT_KICK_SDS, seeds: int = 8, latency: float = 0.10,
             progress=None) -> DisturbanceFit:
    """Fit (sd, tau) of the yaw disturbance and the per-firing kick spread jointly (module doc);
    ``windows``: :func:`frog_sim.multi_period.real_windows` with ``n_max = 1``.

    The two are independent, so their autocovariances add: ``C = K(kick_sd) + (sd / sd0)^2
    U(tau)``, ``K`` and ``U`` each simulated once; ``sd`` matches ``C(0)``, and the grid point
    with the autocorrelations at lags 1 and 2 nearest the robot's is taken. Both on at once
    (other seeds), ``sd`` is rescaled once to ``C(0)`` and the final run is the check.
    """
    resid = real_residuals(sim, windows, latency)
    real_c, real_n = autocovariance(list(resid.values()))
    rho = real_c / real_c[0]
    sequences = run_sequences(windows)
    kick_c = {k: autocovariance(simulated_residuals(sim, sequences, 0.0, 1.0, seeds, latency, kick_sd=k,
                                                    progress=progress))[0] if k > 0 else np.zeros(MAX_LAG + 1)
              for k in kick_sds}
    ou_c = {t: autocovariance(simulated_residuals(sim, sequences, REFERENCE_SD, t, seeds, latency,
                                                  progress=progress))[0] for t in taus}
    grid = []
    for k in kick_sds:
        for t in taus:
            share = (real_c[0] - kick_c[k][0]) / ou_c[t][0]
            if share <= 0:          # this kick spread alone is noisier than the robot's residual
                continue
            c = kick_c[k] + share * ou_c[t]
            grid.append({'kick_sd': float(k), 'tau': float(t), 'sd': REFERENCE_SD * math.sqrt(share),
                         'c': c.tolist(),
                         'score': float((c[1] / c[0] - rho[1]) ** 2 + (c[2] / c[0] - rho[2]) ** 2)})
    if not grid:
        raise ValueError('every kick spread of the grid alone exceeds the residual variance')
    best = min(grid, key=lambda g: g['score'])
    sd, tau, kick = best['sd'], best['tau'], best['kick_sd']
    # both on at once, twice the draws, other seeds: sd rescaled to C(0) until within 5 % (the
    # waterline friction makes the response to a small torque less than linear); then a fresh check run
    for it in range(MAX_RESCALES):
        both = simulated_residuals(sim, sequences, sd, tau, 2 * seeds, latency, kick_sd=kick, seed=77 + it,
                                   progress=progress)
        ratio = real_c[0] / autocovariance(both)[0][0]
        sd *= math.sqrt(ratio)
        if abs(ratio - 1.0) < 0.05:
            break
    c, _ = autocovariance(simulated_residuals(sim, sequences, sd, tau, 2 * seeds, latency, kick_sd=kick, seed=5077,
                                              progress=progress))
    sim.set_yaw_disturbance(sd, tau, seed=11)
    sim.set_kick_variability(kick, seed=12)
    b_real, b_sim = mp.heading_wander(sim, windows, draws=4, latency=latency)
    sim.set_yaw_disturbance(0.0, 1.0)
    sim.set_kick_variability(0.0)
    return DisturbanceFit(sd=sd, tau=tau, kick_sd=kick, real_c=real_c.tolist(), real_n=real_n.tolist(),
                          fitted_c=c.tolist(), b_wander_real=b_real, b_wander_fitted=b_sim,
                          held_out_r2=held_out_predictability(windows, resid), grid=grid,
                          seeds=seeds, latency=latency)


def format_fit(fit: DisturbanceFit) -> str:
    deg2 = math.degrees(1.0) ** 2
    lines = ['residual heading change per period, autocovariance C(j) [deg^2] (pooled over the runs):',
             'lag j                 ' + ''.join(f'{j:>9d}' for j in range(len(fit.real_c))),
             'robot                 ' + ''.join(f'{v * deg2:9.2f}' for v in fit.real_c),
             'pairs                 ' + ''.join(f'{n:9d}' for n in fit.real_n)]
    for g in fit.grid:
        lines.append(f"kick {g['kick_sd']:4.2f} tau {g['tau']:4.2f} s" + ''.join(f'{v * deg2:9.2f}' for v in g['c'])
                     + f"   sd {g['sd']:.2e} N m, score {g['score']:.4f}")
    lines.append('fitted, check run     ' + ''.join(f'{v * deg2:9.2f}' for v in fit.fitted_c)
                 + f'   (both on, {2 * fit.seeds} other draws per run; C(3), C(4) not fitted)')
    lines.append(f'B wander (mean |heading change| of the B decisions, not fitted): robot '
                 f'{math.degrees(fit.b_wander_real):.1f} deg, fitted {math.degrees(fit.b_wander_fitted):.1f} deg '
                 f'(the robot\'s includes its left turn under B, +1.6 deg per period: a limb asymmetry, '
                 f'the twin\'s limb_strength_sd)')
    lines.append('RMS heading error after N periods that the residual alone gives (deg): '
                 + ', '.join(f'N = {n}: {math.degrees(implied_rms(fit.real_c, n)):.1f}' for n in range(1, 5)))
    lines.append(f'held-out R^2 of the residual on (primitive, previous primitive, velocity), leave one run out: '
                 f'{fit.held_out_r2:.2f} (what a better deterministic model of the state could remove)')
    lines.append(f'identified: yaw_disturbance_sd = {fit.sd:.3e} N m, yaw_disturbance_tau_s = {fit.tau:g} s, '
                 f'kick_strength_sd = {fit.kick_sd:g} ({fit.seeds} seeds per run)')
    return '\n'.join(lines)


def plot_fit(fit: DisturbanceFit, file) -> None:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    deg2 = math.degrees(1.0) ** 2
    lags = np.arange(len(fit.real_c))
    fig, ax = plt.subplots(figsize=(6.5, 4))
    ax.plot(lags, np.array(fit.real_c) * deg2, 'ko-', lw=2, label='robot (residual of the model)')
    for g in fit.grid:
        if g['kick_sd'] == fit.kick_sd:
            ax.plot(lags, np.array(g['c']) * deg2, '-', alpha=0.5, label=f"tau {g['tau']:g} s")
    ax.plot(lags, np.array(fit.fitted_c) * deg2, 'r^--',
            label=f'fitted (tau {fit.tau:g} s, kick sd {fit.kick_sd:g}), rerun')
    ax.axhline(0, color='grey', lw=0.5)
    ax.set_xlabel('lag [decisions]')
    ax.set_ylabel('C(j) [deg$^2$]')
    ax.set_title('heading residual per period: autocovariance')
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(file, dpi=120)
    plt.close(fig)
