"""The real robot's closed-loop logs as per-decision transitions.

A hardware log (``shared/data/frog/hardware_runs/<run>.csv``, see its README) holds the
overhead camera's tag pose at ~14 fps and the last primitive sent. From it we rebuild
what the planner's transition model needs, for every decision:

1. **Start-up burst.** The log starts with ~50 rows ~1 ms apart (the tracker's queue
   draining; stale poses with fresh stamps). The burst ends at the first row after which
   five consecutive frame gaps are at least ``min_frame_gap`` (15 ms, a fifth of the
   70 ms frame interval); that row (the last one drained) is dropped too.
2. **Decision times.** The action column changes only when the chosen primitive changes,
   so decisions are not all visible. The change times are fitted to ``T0 + k P``
   (least squares, integer ``k`` by rounding; ``P`` by a scan over 1.0-2.0 s, which
   excludes the harmonics ``P/2``; then refined); the fit's residuals (RMS, max, in
   frames) say how well it fits. Every ``T0 + k P`` inside the log is a decision; its
   primitive is the action shown ``action_probe`` (0.25 s) after it (later than any
   frame lag, earlier than the next decision).
3. **Poses and velocities** at a decision come from local least-squares fits of x, y and
   the unwrapped theta: the pose from a quadratic over ``[t - 0.40, t + 0.12]`` s, the
   velocity from a line over ``[t - 0.45, t + 0.05]`` s (the kick starts 0.15-0.2 s after
   a decision), never from the raw difference columns.
   The robot heading is ``theta + tag_offset`` (the tag is turned by about +6 deg on the
   robot: under B the travel direction is about -6 deg from theta).
4. **Transition** of decision k: the pose change from ``d_k`` to ``d_k + P`` in the start
   body frame (dx forward, dy left, dheading), with the body velocity (u, v, r) at
   ``d_k`` as its initial state.

The tag is taken to sit at the centre of mass (its offset is not documented; a tag
2 cm off the COM would move dx/dy by up to ~5 mm in a 14 deg turn).
"""
from __future__ import annotations

import csv
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
from frog_common import se2
from frog_common.primitives import PRIMITIVE_NAMES

#: Runs of ``hardware_runs/`` (README): two lines, four sinusoids and three ellipses.
HARDWARE_RUNS = ('line1', 'line2', 'sin1', 'sin2', 'sin3', 'sin4', 'ellipse1', 'ellipse3', 'ellipse5')
#: Decision to firing [s] on the robot: the relay, BLE and firmware (the README's heading starts
#: to change 0.15-0.2 s after a decision; the SMA's own delay is in the eq. 9 profile). The
#: replays of its logs fire this long after each decision.
DECISION_TO_FIRING_S = 0.10
#: Tag heading offset [rad]: robot heading = theta + offset (README: travel under B is
#: about -6 deg from theta; re-measured by :func:`estimate_tag_offset`).
DEFAULT_TAG_OFFSET = np.radians(-6.0)


@dataclass
class HardwareLog:
    """One closed-loop run after the start-up burst (SI, time from the first kept row).

    Attributes
    ----------
    name : str
    time : ndarray, shape (T,)
        [s] since the first kept frame.
    x, y : ndarray, shape (T,)
        Tag position [m] (camera world frame).
    theta : ndarray, shape (T,)
        Tag heading [rad], unwrapped.
    action : ndarray of str, shape (T,)
        Last primitive sent ('A'-'I').
    dropped_rows : int
        Rows of the start-up burst that were dropped.
    start_ms : float
        Timestamp of the first kept row [ms since midnight].
    """

    name: str
    time: np.ndarray
    x: np.ndarray
    y: np.ndarray
    theta: np.ndarray
    action: np.ndarray
    dropped_rows: int = 0
    start_ms: float = 0.0

    @property
    def duration(self) -> float:
        """Time span of the kept frames [s]."""
        return float(self.time[-1] - self.time[0])


def burst_end(stamps_s: np.ndarray, min_frame_gap: float = 0.015, run: int = 5) -> int:
    """Index of the first row after the start-up burst (see module doc)."""
    gaps = np.diff(np.asarray(stamps_s, dtype=float))
    ok = gaps >= min_frame_gap
    for i in range(len(ok) - run + 1):
        if ok[i:i + run].all():
            # row i is the last one drained if the gap before it was a burst gap
            return i + 1 if i > 0 and not ok[i - 1] else i
    raise ValueError('the log never settles to a frame rate: no 5 consecutive frame gaps '
                     f'>= {min_frame_gap * 1e3:.0f} ms')


def read_hardware_log(path: Path | str, min_frame_gap: float = 0.015) -> HardwareLog:
    """Read ``<run>.csv`` of ``hardware_runs/`` and drop the start-up burst.

    Raises
    ------
    ValueError
        If the file has no frames, a row is malformed or an action is not A-I (the
        message names the file and the line).
    """
    path = Path(path)
    stamps, xs, ys, ths, acts = [], [], [], [], []
    with open(path, newline='') as fh:
        reader = csv.reader(fh)
        for lineno, row in enumerate(reader, start=1):
            if lineno <= 2 or not row:
                continue
            try:
                stamps.append(float(row[0]))
                xs.append(float(row[1]))
                ys.append(float(row[2]))
                ths.append(float(row[3]))
            except (ValueError, IndexError):
                raise ValueError(f'{path}:{lineno}: expected Timestamp,x,y,theta,... numbers, '
                                 f'got {row[:4]!r}') from None
            act = row[-1].strip().upper()
            if act not in PRIMITIVE_NAMES:
                raise ValueError(f'{path}:{lineno}: last column {row[-1]!r} is not a primitive A-I')
            acts.append(act)
    if len(stamps) < 10:
        raise ValueError(f'{path}: only {len(stamps)} frames')
    stamps = np.array(stamps) / 1000.0
    order = np.argsort(stamps, kind='stable')
    if not np.all(order == np.arange(len(order))):
        raise ValueError(f'{path}: timestamps are not increasing')
    i0 = burst_end(stamps, min_frame_gap)
    t = stamps[i0:]
    return HardwareLog(name=path.stem, time=t - t[0], x=np.array(xs[i0:]), y=np.array(ys[i0:]),
                       theta=np.unwrap(np.array(ths[i0:])), action=np.array(acts[i0:]),
                       dropped_rows=int(i0), start_ms=float(t[0] * 1000.0))


def read_hardware_runs(folder: Path | str, runs=HARDWARE_RUNS) -> dict:
    """``{name: HardwareLog}`` of the runs in ``folder``."""
    folder = Path(folder)
    return {name: read_hardware_log(folder / f'{name}.csv') for name in runs}


# ------------------------------------------------------------------ decisions
@dataclass
class DecisionFit:
    """Decision times ``T0 + k P`` fitted to the action change times.

    Attributes
    ----------
    t0, period : float
        [s]
    change_times : ndarray
        Times of the frames where the action changed [s].
    change_index : ndarray of int
        ``k`` of each change.
    residual_rms, residual_max : float
        Of the change times about the fit [s].
    frame_interval : float
        Median frame interval of the log [s] (for residuals in frames).
    """

    t0: float
    period: float
    change_times: np.ndarray
    change_index: np.ndarray
    residual_rms: float
    residual_max: float
    frame_interval: float

    def decision_times(self, t_end: float, t_start: float | None = None) -> np.ndarray:
        """Every ``T0 + k P`` in ``[t_start (default T0), t_end]``."""
        t_start = self.t0 if t_start is None else t_start
        k0 = int(np.ceil((t_start - self.t0) / self.period - 1e-9))
        k1 = int(np.floor((t_end - self.t0) / self.period + 1e-9))
        return self.t0 + self.period * np.arange(k0, k1 + 1)


def _lsq_grid(times, period):
    k = np.round((times - times[0]) / period)
    a = np.column_stack([np.ones_like(k), k])
    coef, *_ = np.linalg.lstsq(a, times, rcond=None)
    res = times - a @ coef
    return coef, k, res


def fit_decision_times(log: HardwareLog, period_range=(1.0, 2.0), step: float = 5e-4,
                       frame_lag: float = 0.5) -> DecisionFit:
    """Fit the action change times of ``log`` to ``T0 + k P`` (see module doc).

    A decision shows in the first frame after it, on average half a frame late: ``T0`` is
    moved ``frame_lag`` median frame intervals earlier (0 for decisions taken on a frame).

    Raises
    ------
    ValueError
        With fewer than 3 changes (the period is not determined).
    """
    change = np.nonzero(log.action[1:] != log.action[:-1])[0] + 1
    times = log.time[change]
    if len(times) < 3:
        raise ValueError(f'{log.name}: {len(times)} action changes; at least 3 are needed to fit '
                         'the decision period')
    best = None
    for p in np.arange(period_range[0], period_range[1] + step / 2, step):
        coef, k, res = _lsq_grid(times, p)
        rms = float(np.sqrt(np.mean(res ** 2)))
        if best is None or rms < best[0] - 1e-12:
            best = (rms, p)
    coef, k, res = _lsq_grid(times, best[1])
    # refine: with k fixed, the least-squares slope is the period
    t0, period = float(coef[0]), float(coef[1])
    k = k - np.round((t0 - times[0]) / period)
    frame = float(np.median(np.diff(log.time)))
    return DecisionFit(t0=t0 - frame_lag * frame, period=period, change_times=times, change_index=k.astype(int),
                       residual_rms=float(np.sqrt(np.mean(res ** 2))),
                       residual_max=float(np.abs(res).max()), frame_interval=frame)


def action_at(log: HardwareLog, t: float) -> str:
    """Action shown by the last frame at or before ``t``."""
    i = int(np.searchsorted(log.time, t, side='right')) - 1
    return str(log.action[max(i, 0)])


# ------------------------------------------------------------------ local fits
@dataclass(frozen=True)
class LocalPose:
    """Pose and velocity of the robot (heading incl. tag offset) at one time, world frame."""

    time: float
    x: float
    y: float
    heading: float
    vx: float
    vy: float
    yaw_rate: float
    n_frames: int

    def body_velocity(self) -> tuple[float, float]:
        """(forward, left) [m/s]."""
        c, s = np.cos(self.heading), np.sin(self.heading)
        return float(c * self.vx + s * self.vy), float(-s * self.vx + c * self.vy)


def _poly_fit(log, t, before, after, degree):
    sel = (log.time >= t - before) & (log.time <= t + after)
    n = int(sel.sum())
    if n < degree + 2:
        raise ValueError(f'{log.name}: {n} frames in [{t - before:.2f}, {t + after:.2f}] s; '
                         f'need {degree + 2}')
    a = np.vander(log.time[sel] - t, degree + 1, increasing=True)
    coef, *_ = np.linalg.lstsq(a, np.column_stack([log.x[sel], log.y[sel], log.theta[sel]]), rcond=None)
    return coef, n


def local_pose(log: HardwareLog, t: float, tag_offset: float = DEFAULT_TAG_OFFSET,
               before: float = 0.40, after: float = 0.12, degree: int = 2,
               velocity_window: tuple | None = (0.45, 0.05)) -> LocalPose:
    """Local least-squares fits of x, y, theta around ``t``.

    The pose is the value at ``t`` of a polynomial of ``degree`` over ``[t - before,
    t + after]``. The velocity is the slope of a straight line over ``velocity_window``
    (before, after) -- the coasting phase ahead of a kick, where a line is a good model
    and its slope is ~3x less noisy than the end slope of a quadratic -- or, with
    ``velocity_window=None``, the slope of the same polynomial at ``t``.

    Raises
    ------
    ValueError
        If too few frames fall in a window.
    """
    coef, n = _poly_fit(log, t, before, after, degree)
    vel = coef[1]
    if velocity_window is not None:
        vcoef, _ = _poly_fit(log, t, velocity_window[0], velocity_window[1], 1)
        vel = vcoef[1]
    return LocalPose(time=float(t), x=float(coef[0, 0]), y=float(coef[0, 1]),
                     heading=float(coef[0, 2] + tag_offset), vx=float(vel[0]), vy=float(vel[1]),
                     yaw_rate=float(vel[2]), n_frames=n)


@dataclass
class Transition:
    """One decision's transition over one period (start body frame; SI).

    Attributes
    ----------
    run : str
    index : int
        Decision number k within the run.
    time : float
        Decision time [s] (log time).
    period : float
        [s]
    primitive : str
        'A'-'I'.
    previous : str
        Primitive of the decision before ('' for the first).
    forward, lateral, yaw_rate : float
        Body velocity at the decision [m/s, m/s, rad/s].
    dx, dy, dheading : float
        Pose change after one period [m, m, rad].
    """

    run: str
    index: int
    time: float
    period: float
    primitive: str
    previous: str
    forward: float
    lateral: float
    yaw_rate: float
    dx: float
    dy: float
    dheading: float
    extra: dict = field(default_factory=dict)

    def as_dict(self) -> dict:
        """Plain dict (JSON)."""
        return asdict(self)


def relative_pose(p0: LocalPose, p1: LocalPose) -> tuple[float, float, float]:
    """(dx, dy) of ``p1`` in the body frame of ``p0`` and the heading change [m, m, rad]."""
    d = se2.relative_pose((p0.x, p0.y, p0.heading), (p1.x, p1.y, p1.heading))
    return float(d[0]), float(d[1]), float(d[2])


def measure_transitions(log: HardwareLog, fit: DecisionFit | None = None,
                        tag_offset: float = DEFAULT_TAG_OFFSET, action_probe: float = 0.25,
                        **window) -> list[Transition]:
    """Every decision of ``log`` whose whole period (and its pose windows) is in the log."""
    fit = fit or fit_decision_times(log)
    before = window.get('before', 0.40)
    after = window.get('after', 0.12)
    times = fit.decision_times(t_end=log.time[-1] - fit.period - after,
                               t_start=max(fit.t0, log.time[0] + before))
    out = []
    prev = ''
    for t in times:
        k = int(round((t - fit.t0) / fit.period))
        p0 = local_pose(log, t, tag_offset, **window)
        p1 = local_pose(log, t + fit.period, tag_offset, **window)
        dx, dy, dh = relative_pose(p0, p1)
        u, v = p0.body_velocity()
        prim = action_at(log, t + action_probe)
        out.append(Transition(run=log.name, index=k, time=float(t), period=fit.period, primitive=prim,
                              previous=prev, forward=u, lateral=v, yaw_rate=p0.yaw_rate,
                              dx=dx, dy=dy, dheading=dh))
        prev = prim
    return out


def heading_curve(log: HardwareLog, t: float, duration: float, dt: float = 0.05,
                  tag_offset: float = DEFAULT_TAG_OFFSET) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Heading change and yaw rate after ``t`` on a regular grid (local fits; +-0.15 s windows).

    Returns
    -------
    tau, dheading, yaw_rate : ndarray
        [s], [rad], [rad/s]; NaN where the window leaves the log.
    """
    tau = np.arange(0.0, duration + 1e-9, dt)
    h = np.full(tau.shape, np.nan)
    r = np.full(tau.shape, np.nan)
    for i, s in enumerate(tau):
        try:
            p = local_pose(log, t + s, tag_offset, before=0.15, after=0.15, velocity_window=None)
        except ValueError:
            continue
        h[i], r[i] = p.heading, p.yaw_rate
    p0 = local_pose(log, t, tag_offset)
    return tau, h - p0.heading, r


def estimate_tag_offset(logs, primitive: str = 'B', min_distance: float = 0.01) -> tuple[float, float, int]:
    """Angle between the travel direction and theta over the ``primitive`` periods [rad].

    Uses the decisions (with offset 0) whose displacement exceeds ``min_distance``; the
    travel direction is compared with the mean of theta at both ends.

    Returns
    -------
    mean, sd : float
        [rad] (robot heading = theta + mean, if the primitive drives straight ahead).
    n : int
    """
    vals = []
    for log in logs:
        for tr in measure_transitions(log, tag_offset=0.0):
            if tr.primitive != primitive or np.hypot(tr.dx, tr.dy) < min_distance:
                continue
            # direction of the displacement in the start tag frame, minus half the turn
            vals.append(np.arctan2(tr.dy, tr.dx) - 0.5 * tr.dheading)
    if not vals:
        raise ValueError(f'no {primitive} decision with more than {min_distance * 1e3:.0f} mm travel')
    vals = np.array(vals)
    return float(vals.mean()), float(vals.std(ddof=1) if len(vals) > 1 else np.nan), len(vals)


# ------------------------------------------------------------------ synthetic logs
@dataclass
class SyntheticLog:
    """A log written by :func:`synthesize_log` with its ground truth."""

    path: Path
    decision_times: np.ndarray     # log time of each decision [s]
    primitives: list
    period: float
    tag_offset: float
    truth: list                    # Transition per decision (exact, from the simulation)
    burst_rows: int


def synthesize_log(sim, primitives, path: Path | str, period: float = 1.43, first_decision: float = 1.0,
                   latency: float = 0.1, frame_interval: float = 0.07, frame_jitter: float = 0.015,
                   position_noise: float = 0.0008, heading_noise: float = np.radians(0.5),
                   tag_offset: float = DEFAULT_TAG_OFFSET, burst_rows: int = 50, tail: float = 1.0,
                   seed: int = 0, start_pose=(0.1, 0.2, 1.0)) -> SyntheticLog:
    """Simulate a primitive sequence and write it as a hardware log (with its truth).

    The robot rests until ``first_decision``; decision k at ``first_decision + k period``
    fires its primitive ``latency`` later; frames come every ``frame_interval`` +- uniform
    ``frame_jitter``; poses get Gaussian noise; the written theta is the robot heading minus
    ``tag_offset``; the log starts with ``burst_rows`` rows 1 ms apart (stale rest poses).

    Parameters
    ----------
    sim : FrogSimulation
        Reset and used for the run.
    primitives : sequence of str
    """
    from .schedules import ActivationSchedule
    rng = np.random.default_rng(seed)
    sim.reset()
    sim.set_pose(*start_pose)
    decisions = first_decision + period * np.arange(len(primitives))
    sched = ActivationSchedule.primitive_sequence(primitives, period=period, pulse=sim.params.pulse_duration,
                                                  start=first_decision + latency)
    sim.set_schedule(sched)
    total = decisions[-1] + period + tail
    traj = sim.run(total, record_interval=0.005)
    frames = [0.0]
    while frames[-1] < total - frame_interval:
        frames.append(frames[-1] + frame_interval + rng.uniform(-frame_jitter, frame_jitter))
    frames = np.array(frames[:-1]) if frames[-1] > total else np.array(frames)

    def interp(tq):
        x = np.interp(tq, traj.time, traj.com[:, 0])
        y = np.interp(tq, traj.time, traj.com[:, 1])
        h = np.interp(tq, traj.time, traj.heading)
        return x, y, h
    x, y, h = interp(frames)
    x = x + rng.normal(0, position_noise, x.shape)
    y = y + rng.normal(0, position_noise, y.shape)
    theta = np.mod(h - tag_offset + rng.normal(0, heading_noise, h.shape), 2 * np.pi)
    act = np.array(['I'] * len(frames))
    for k, d in enumerate(decisions):
        act[frames >= d] = primitives[k]
    base_ms = 62_000_000.0
    stamps = base_ms + 1000.0 * frames
    path = Path(path)
    with open(path, 'w', newline='') as fh:
        w = csv.writer(fh)
        w.writerow(['CV Data Logger started on:', 'synthetic'])
        w.writerow(['Timestamp (millisec since midnight today)', 'x', 'y', 'theta', 'xdot', 'ydot',
                    'thetadot', 'cost', 'd', 'h', 'p', 'last action'])
        for i in range(burst_rows):   # the tracker's queue draining: stale rest poses 1 ms apart
            w.writerow([f'{base_ms - 1000.0 * frame_interval - burst_rows + i:.0f}', x[0], y[0], theta[0],
                        0, 0, 0, 0, 0, 0, 0, 'I'])
        for i in range(len(frames)):
            j = max(i - 1, 0)
            w.writerow([f'{stamps[i]:.0f}', x[i], y[i], theta[i], x[i] - x[j], y[i] - y[j],
                        theta[i] - theta[j], 0, 0, 0, 0, act[i]])
    truth = []
    prev = ''
    for k, d in enumerate(decisions):
        x0, y0, h0 = interp(np.array([d, d + period]))
        c, s = np.cos(h0[0]), np.sin(h0[0])
        ex, ey = x0[1] - x0[0], y0[1] - y0[0]
        i = int(np.searchsorted(traj.time, d))
        vx, vy = traj.com_velocity[i]
        truth.append(Transition(run=path.stem, index=k, time=float(d), period=period, primitive=primitives[k],
                                previous=prev, forward=float(c * vx + s * vy), lateral=float(-s * vx + c * vy),
                                yaw_rate=float(traj.yaw_rate[i]), dx=float(c * ex + s * ey),
                                dy=float(-s * ex + c * ey), dheading=float(h0[1] - h0[0])))
        prev = primitives[k]
    return SyntheticLog(path=path, decision_times=decisions, primitives=list(primitives), period=period,
                        tag_offset=tag_offset, truth=truth, burst_rows=burst_rows)
