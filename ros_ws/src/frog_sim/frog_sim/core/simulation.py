"""Public API of the frog simulator (no ROS): build, schedule, step/run, read state.

Examples
--------
>>> from frog_sim.core.simulation import FrogSimulation
>>> sim = FrogSimulation()                          # 10 % EGaIn, default dt   # doctest: +SKIP
>>> sim.set_gait(frequency_hz=1.0, phase_offset=0.5)                           # doctest: +SKIP
>>> traj = sim.run(5.0)                                                        # doctest: +SKIP
>>> sim.rigid_body_state().body_velocity                                       # doctest: +SKIP
>>> sim.execute_primitive('C')          # fire primitive C now (front first)  # doctest: +SKIP
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .actuation import ActuationLibrary, CurvatureProfile, profile_value
from .frog_model import FrogModel, build_frog_model
from .integrator import ConvergenceError, ImplicitEulerIntegrator
from .model_parameters import FrogParameters
from .rigid_body import HeadingUnwrapper, RigidBodyState, nodal_velocities, rigid_body_state
from frog_common.primitives import LIMB_NAMES

from .schedules import ActivationSchedule
from .waterline_friction import waterline_friction_coefficients
from .yaw_disturbance import YawDisturbance, torque_forces
from frog_common.version import code_version

#: Default time step [s], chosen from the dt convergence study (``frog-sim convergence``
#: plus finer steps; 10 cycles at 1 Hz, 10 % EGaIn), rerun for the issue-11 fluid model:
#: the 10-cycle displacement is 412.7 / 439.5 / 456.5 / 465.2 / 468.5 / 469.5 / 469.7 mm
#: at dt = 8 / 4 / 2 / 1 / 0.5 / 0.25 / 0.125 ms: changes 26.8, 17.1, 8.6, 3.3, 1.0,
#: 0.2 mm, first order down to 1 ms and faster below (dt -> 0: ~469.7 mm). 2 ms is 2.8 %
#: below it and within 0.7 % / 0.05 % of 1 ms for 30 % EGaIn at 1.3 Hz / 50 % at 2 Hz
#: (4 ms: 2.8 % / 3.3 %), with half the steps of 1 ms. Halving dl (46, 92 edges per side,
#: 1 ms) changes it by 4.6 mm (1.0 %) and 0.4 mm.
DEFAULT_TIME_STEP = 2.0e-3
#: Default Newton force tolerance [N]: ~0.1 % of the nodal drag/inertia forces of a limb
#: during a kick (~1e-3 N). Tightening it to 1e-8 N changes the 10-cycle displacement at
#: 1 Hz by 1e-4 mm (3e-7 relative); it costs ~1.7 more Newton iterations per step.
DEFAULT_FORCE_TOLERANCE = 1e-6
#: The yaw disturbance is held over intervals of this length [s] (its time constant is seconds).
DISTURBANCE_INTERVAL_S = 0.02

__all__ = ['FrogSimulation', 'Trajectory', 'DEFAULT_TIME_STEP', 'ConvergenceError']


@dataclass
class Trajectory:
    """Recorded samples of a run (all SI).

    Attributes
    ----------
    time : ndarray, shape (T,)
        [s]
    positions : ndarray, shape (T, N, 2)
        Node positions [m] (world frame).
    com : ndarray, shape (T, 2)
        Centre of mass [m] (eq. 10).
    heading : ndarray, shape (T,)
        [rad], unwrapped (eq. 11 resolved).
    com_velocity : ndarray, shape (T, 2)
        World-frame COM velocity [m/s].
    body_velocity : ndarray, shape (T, 2)
        COM velocity in the robot frame (forward, left) [m/s].
    yaw_rate : ndarray, shape (T,)
        [rad/s] (eq. 12).
    """

    time: np.ndarray
    positions: np.ndarray
    com: np.ndarray
    heading: np.ndarray
    com_velocity: np.ndarray
    body_velocity: np.ndarray
    yaw_rate: np.ndarray
    metadata: dict = field(default_factory=dict)

    @classmethod
    def from_samples(cls, samples, positions, metadata=None) -> 'Trajectory':
        """Build from lists of :class:`RigidBodyState` and (N, 2) position arrays."""
        return cls(time=np.array([s.time for s in samples]),
                   positions=np.array(positions),
                   com=np.array([s.com for s in samples]).reshape(-1, 2),
                   heading=np.array([s.heading for s in samples]),
                   com_velocity=np.array([s.com_velocity for s in samples]).reshape(-1, 2),
                   body_velocity=np.array([s.body_velocity for s in samples]).reshape(-1, 2),
                   yaw_rate=np.array([s.yaw_rate for s in samples]),
                   metadata=dict(metadata or {}))

    def forward_speed(self, start_time: float) -> float:
        """Mean speed [m/s] along the initial heading: slope of a line fit to the
        displacement after ``start_time`` (as for the calibration runs)."""
        sel = self.time >= start_time
        if sel.sum() < 2:
            raise ValueError(f'fewer than 2 samples after t = {start_time} s')
        h0 = self.heading[0]
        direction = np.array([np.cos(h0), np.sin(h0)])
        dist = (self.com[sel] - self.com[0]) @ direction
        return float(np.polyfit(self.time[sel], dist, 1)[0])


class FrogSimulation:
    """The frog robot simulator: model + actuation + implicit Euler integrator.

    Parameters
    ----------
    params : FrogParameters, optional
        Physical parameters (EGaIn fraction, geometry, fluid ...).
    time_step : float
        dt [s] of every step (default :data:`DEFAULT_TIME_STEP`).
    library : ActuationLibrary, optional
        Fitted curvature profiles (default: loaded from the cache / fitted once).
    solver : {'direct', 'superlu'}
        Linear solver of the Newton steps.
    force_tolerance : float
        Newton residual tolerance [N].

    Notes
    -----
    Typical use: ``set_gait`` or ``set_schedule`` / ``execute_primitive``; then ``step``
    or ``run``; read ``node_positions`` and ``rigid_body_state()``. Start from a moving
    state with ``set_velocity`` (paper eq. 13).
    """

    def __init__(self, params: FrogParameters | None = None, *, time_step: float = DEFAULT_TIME_STEP,
                 library: ActuationLibrary | None = None, solver: str = 'direct',
                 force_tolerance: float = DEFAULT_FORCE_TOLERANCE):
        self.params = params or FrogParameters()
        self.params.validate()
        if not (np.isfinite(time_step) and time_step > 0):
            raise ValueError(f'time_step = {time_step!r} s must be a positive number')
        self.time_step = float(time_step)
        self.library = library or ActuationLibrary.load()
        self._solver = solver
        self._force_tolerance = force_tolerance
        default = self.library.nearest_profile(self.params.egain_vol_pct,
                                               1.0 / self.params.primitive_period)
        self._build(default)

    # ------------------------------------------------------------------ construction
    def _build(self, profile: CurvatureProfile) -> None:
        self.profile = profile
        self.model: FrogModel = build_frog_model(self.params, profile.relaxed_curvature)
        self._actuator = self.model.actuator_arrays(profile)
        self._nominal_rows = self._actuator.limb_profile.copy()
        self._apply_limb_strength()
        self.integrator = ImplicitEulerIntegrator(
            self.model.network, self.model.mass, fluid_density=self.params.fluid_density,
            actuator=self._actuator, solver=self._solver, force_tolerance=self._force_tolerance,
            body_damping=(self.params.surge_damping_linear, self.params.sway_damping_linear,
                          self.params.yaw_damping_linear),
            reference=self.model.reference_pose,
            waterline_friction=waterline_friction_coefficients(self.params.waterline_friction,
                                                               self.params.body_side_length))
        self._schedule = ActivationSchedule.empty()
        self._gait = None
        self._horizon = -np.inf
        self._unwrap = HeadingUnwrapper(0.0)
        self._sync_schedule(force=True)

    def reset(self) -> None:
        """Back to the reference pose at rest, t = 0, no schedule (keeps the profile).

        Cheap (no rebuild of the model or the solver plan): used between the many short
        runs of sweeps and motion libraries.
        """
        integ = self.integrator
        integ.set_state(x=self.model.network.positions.ravel(), v=np.zeros(integ.v.size))
        integ.time = 0.0
        integ.kappa0[:] = self.model.network.bend_natural_curvature
        integ.ei[:] = self.model.network.bend_stiffness
        integ.ea[:] = self.model.network.edge_stretching_stiffness
        integ.external_force[:] = 0.0
        if getattr(self, '_disturbance', None) is not None:     # mid-run, as it were
            self._disturbance.torque = self._disturbance.stationary_draw()
            self._disturbance_on = False
        self._schedule = ActivationSchedule.empty()
        self._gait = None
        self._horizon = -np.inf
        self._unwrap = HeadingUnwrapper(0.0)
        self._sync_schedule(force=True)

    def use_profile(self, frequency_hz: float, exact: bool = True) -> CurvatureProfile:
        """Drive the limbs with the profile measured at ``frequency_hz`` for this EGaIn.

        The model is rebuilt only if the relaxed curvature changes (i.e. at t = 0);
        later calls just switch the profile. Returns the chosen profile.

        Raises
        ------
        ValueError
            If ``exact`` and the frequency was not measured for this EGaIn fraction.
        """
        lib = self.library
        prof = (lib.profile(self.params.egain_vol_pct, frequency_hz) if exact
                else lib.nearest_profile(self.params.egain_vol_pct, frequency_hz))
        if prof is self.profile:
            return prof
        if self.time == 0.0 and np.allclose(self.integrator.v, 0.0):
            # still at rest at t = 0: rebuild so the limbs start at this profile's relaxed
            # curvature, keeping the pose the user may have set
            schedule, gait = self._schedule, self._gait
            pose = self.rigid_body_state()
            self._build(prof)
            self._schedule, self._gait = schedule, gait
            self.set_pose(pose.com[0], pose.com[1], pose.heading)
        else:
            self.profile = prof
            self._actuator.limb_profile[:] = prof.as_row()
            self._nominal_rows = self._actuator.limb_profile.copy()
            self._apply_limb_strength()
        self._sync_schedule(force=True)
        return prof

    def set_limb_strength(self, strength=None) -> None:
        """Scale each limb's kick: the excursion of its eq. 9 curvature from rest times a factor.

        Real limbs differ (wire, attachment, EGaIn fill); the digital twin draws one factor
        per limb. ``strength`` maps limb names ('FL', 'FR', 'BL', 'BR') to factors > 0
        (missing = 1); None restores the nominal kick. The relaxed curvature is unchanged.
        """
        strength = dict(strength or {})
        bad = {k: v for k, v in strength.items() if k not in LIMB_NAMES or not (np.isfinite(v) and v > 0)}
        if bad:
            raise ValueError(f'limb strengths {bad} need limb names {LIMB_NAMES} and finite factors > 0')
        self._limb_strength = strength
        self._apply_limb_strength()

    @property
    def limb_strength(self) -> dict:
        """Kick strength factor of each limb (1 = nominal)."""
        return {l: float(getattr(self, '_limb_strength', {}).get(l, 1.0)) for l in LIMB_NAMES}

    def set_realism(self, seed: int, limb_strength_sd: float = 0.0, kick_strength_sd: float = 0.0,
                    yaw_disturbance_sd: float = 0.0, yaw_disturbance_tau: float = 2.0) -> dict:
        """The digital twin's robot-to-robot and kick-to-kick variation, drawn from ``seed``.

        Each limb's strength from N(1, ``limb_strength_sd``^2) (clipped to 0.2-2;
        :meth:`set_limb_strength`), each firing's spread (:meth:`set_kick_variability`, seed
        + 1) and the tank's yaw torque (:meth:`set_yaw_disturbance`, seed + 2). The same seed
        and spreads make the same robot wherever it is simulated (``sim_node``, the in-process
        evaluator). A spread of 0 leaves that part nominal. Returns the limb strengths.
        """
        if limb_strength_sd > 0:
            rng = np.random.default_rng(seed)
            factors = np.clip(1.0 + limb_strength_sd * rng.standard_normal(len(LIMB_NAMES)), 0.2, 2.0)
            self.set_limb_strength(dict(zip(LIMB_NAMES, factors.tolist())))
        if kick_strength_sd > 0:
            self.set_kick_variability(kick_strength_sd, seed=seed + 1)
        if yaw_disturbance_sd > 0:
            self.set_yaw_disturbance(yaw_disturbance_sd, yaw_disturbance_tau, seed=seed + 2)
        return self.limb_strength

    def set_kick_variability(self, sd: float, seed: int | None = None) -> None:
        """Let every firing vary: each limb fired by :meth:`fire_limbs` or :meth:`execute_primitive`
        kicks with its strength times an independent factor ``N(1, sd)`` (clipped to 0.2-2).

        The real robot's kicks differ from one to the next (SMA heating with the battery's
        charge and the water temperature, the wire's contact): on the straight runs its
        heading wanders by several degrees per B period, which a symmetric kick cannot do.
        The factor holds until that limb fires again; scheduled sequences
        (:meth:`set_schedule`) are not varied. ``sd = 0`` turns it off.
        """
        if not (np.isfinite(sd) and 0.0 <= sd < 1.0):
            raise ValueError(f'kick variability sd = {sd!r} must be in [0, 1)')
        self._kick_sd = float(sd)
        self._kick_rng = np.random.default_rng(seed)
        self._firing_factor = {}
        self._apply_limb_strength()

    def set_yaw_disturbance(self, sd: float, tau: float, seed: int | None = None) -> None:
        """A slowly varying yaw torque about the COM (:mod:`~frog_sim.core.yaw_disturbance`: an
        Ornstein-Uhlenbeck process, stationary sd ``sd`` [N m], time constant ``tau`` [s]), held
        over each :data:`DISTURBANCE_INTERVAL_S` of :meth:`step`. ``sd = 0`` turns it off.

        The tank is calm until the frog swims: the torque acts from the first limb firing after
        this call or :meth:`reset` on (the circulation is the robot's own wake; a frog waiting
        for its first command stays where it was put)."""
        self._disturbance = YawDisturbance(sd, tau, seed) if sd > 0 else None
        self._disturbance_on = False
        self.integrator.external_force[:] = 0.0

    @property
    def yaw_disturbance(self) -> YawDisturbance | None:
        """The yaw disturbance process (its ``torque`` [N m] now), or None when off."""
        return getattr(self, '_disturbance', None)

    def _swimming(self) -> None:
        self._disturbance_on = True

    def _draw_kicks(self, limbs) -> None:
        if len(limbs):
            self._swimming()
        if getattr(self, '_kick_sd', 0.0) <= 0.0:
            return
        for limb in limbs:
            self._firing_factor[limb] = float(np.clip(1.0 + self._kick_sd * self._kick_rng.standard_normal(), 0.2, 2.0))
        self._apply_limb_strength()

    def _apply_limb_strength(self) -> None:
        # eq. 9 rows: c1/(1 + exp(-c2 (t - c3))) + c4 for heating (0-3) and cooling (4-7);
        # scaling c1 and c4's offset from rest scales the whole excursion, keeping the rest
        rows = self._nominal_rows.copy()
        firing = getattr(self, '_firing_factor', {})
        for lid, limb in enumerate(LIMB_NAMES):
            s = self.limb_strength[limb] * firing.get(limb, 1.0)
            if s != 1.0:
                rest = profile_value(rows[lid], -1.0)
                for c1, c4 in ((0, 3), (4, 7)):
                    rows[lid, c1] *= s
                    rows[lid, c4] = rest + s * (rows[lid, c4] - rest)
        self._actuator.limb_profile[:] = rows

    # ------------------------------------------------------------------ schedules
    def set_gait(self, frequency_hz: float, phase_offset: float = 0.5, start: float | None = None,
                 duration: float | None = None) -> None:
        """Swim a periodic gait (all four limbs; rear pair ``phase_offset`` of a cycle later).

        Parameters
        ----------
        frequency_hz : float
            Must be a measured frequency for the model's EGaIn fraction.
        phase_offset : float
            In [0, 1).
        start : float, optional
            First firing time [s] (default: now).
        duration : float, optional
            Stop firing after this many seconds (default: forever).
        """
        ActivationSchedule.gait(frequency_hz, phase_offset, 0.0)  # validates
        self.use_profile(frequency_hz)
        start = self.time if start is None else float(start)
        self._gait = (float(frequency_hz), float(phase_offset), start,
                      np.inf if duration is None else float(duration))
        self._swimming()
        self._sync_schedule(force=True)

    def set_schedule(self, schedule: ActivationSchedule, profile_frequency_hz: float | None = None) -> None:
        """Replace all firings by ``schedule`` (and stop any gait).

        ``profile_frequency_hz`` picks the measured profile (default: nearest to one
        primitive per ``primitive_period``).
        """
        if profile_frequency_hz is None:
            profile_frequency_hz = 1.0 / self.params.primitive_period
            self.use_profile(profile_frequency_hz, exact=False)
        else:
            self.use_profile(profile_frequency_hz)
        self._gait = None
        self._schedule = schedule
        if any(len(schedule.times(l)) for l in LIMB_NAMES):
            self._swimming()
        self._sync_schedule(force=True)

    def execute_primitive(self, primitive, start: float | None = None) -> None:
        """Fire a primitive (id 0-8 or 'A'-'I'): front limbs at ``start`` (default now),
        rear limbs one pulse later. Adds to the current schedule; stops a running gait.

        Raises
        ------
        ValueError
            For an unknown primitive.
        """
        start = self.time if start is None else float(start)
        extra = ActivationSchedule.primitive(primitive, start, self.params.pulse_duration)
        self._draw_kicks([l for l in LIMB_NAMES if len(extra.times(l))])
        if self._gait is not None:
            self._schedule = self._schedule.merged(self._gait_schedule(until=self.time))
            self._gait = None
            self.use_profile(1.0 / self.params.primitive_period, exact=False)
        self._schedule = self._schedule.merged(extra)
        self._sync_schedule(force=True)

    def fire_limbs(self, limbs, start: float | None = None) -> None:
        """Fire the named limbs (e.g. ``['FL', 'BR']``) at ``start`` (default now)."""
        start = self.time if start is None else float(start)
        self._draw_kicks(limbs)
        extra = ActivationSchedule({l: [start] for l in limbs})
        self._schedule = self._schedule.merged(extra)
        self._sync_schedule(force=True)

    def _gait_schedule(self, until: float) -> ActivationSchedule:
        f, phase, start, duration = self._gait
        span = min(until, start + duration) - start
        if span < 0:
            return ActivationSchedule.empty()
        return ActivationSchedule.gait(f, phase, span + 1e-12, start=start)

    def _sync_schedule(self, force=False, until=None) -> None:
        """Push firing times covering at least ``until`` to the numba arrays."""
        until = self.time if until is None else until
        if not force and until < self._horizon:
            return
        sched = self._schedule
        horizon = np.inf
        if self._gait is not None:
            horizon = until + 10.0
            sched = sched.merged(self._gait_schedule(until=horizon))
        self._horizon = horizon
        self._actuator.set_activation_times(sched.per_limb())
        self.integrator.update_actuation(self.time)

    @property
    def schedule(self) -> ActivationSchedule:
        """Firings known so far (explicit ones plus the gait up to the current horizon)."""
        if self._gait is None:
            return self._schedule
        return self._schedule.merged(self._gait_schedule(until=self._horizon))

    def last_firings(self) -> dict:
        """Each limb's last firing up to now [s] (the simulator's clock; limbs never fired are left
        out): what a robot's planner knows from what its bridge fired."""
        out = {}
        for limb in LIMB_NAMES:
            times = self.schedule.times(limb)
            times = times[times <= self.time + 1e-12]
            if times.size:
                out[limb] = float(times[-1])
        return out

    # ------------------------------------------------------------------ state
    @property
    def time(self) -> float:
        """Simulated time [s]."""
        return self.integrator.time

    @property
    def node_positions(self) -> np.ndarray:
        """Node positions, shape (N, 2) [m] (a copy)."""
        return self.integrator.x.reshape(-1, 2).copy()

    @property
    def node_velocities(self) -> np.ndarray:
        """Node velocities, shape (N, 2) [m/s] (a copy)."""
        return self.integrator.v.reshape(-1, 2).copy()

    @property
    def limb_curvatures(self) -> dict:
        """Current natural curvature command of each limb [1/m] (unsigned)."""
        out = {}
        for limb in LIMB_NAMES:
            b = self.model.limb_bends[limb][0]
            out[limb] = float(self.integrator.kappa0[b] * self.model.limb_sign[limb])
        return out

    def rigid_body_state(self) -> RigidBodyState:
        """Centre of mass, heading, velocities and yaw rate now (eq. 10-12)."""
        return rigid_body_state(self.time, self.node_positions, self.node_velocities,
                                self.model.mass, self.model.reference_pose, self._unwrap)

    def set_velocity(self, forward: float = 0.0, lateral: float = 0.0, yaw_rate: float = 0.0,
                     frame: str = 'body') -> None:
        """Give every node the velocity of a rigid motion (paper eq. 13).

        Parameters
        ----------
        forward, lateral : float
            COM velocity [m/s]; in the robot frame (``frame='body'``: forward = x_frog,
            lateral = y_frog to the left) or the world frame (``frame='world'``: x, y).
        yaw_rate : float
            [rad/s], counter-clockwise positive.
        """
        if frame not in ('body', 'world'):
            raise ValueError(f"frame = {frame!r}, expected 'body' or 'world'")
        v = np.array([forward, lateral], dtype=float)
        if frame == 'body':
            h = self.rigid_body_state().heading
            c, s = np.cos(h), np.sin(h)
            v = np.array([c * v[0] - s * v[1], s * v[0] + c * v[1]])
        vel = nodal_velocities(self.node_positions, self.model.mass, v, yaw_rate)
        self.integrator.set_state(v=vel)

    def set_pose(self, x: float, y: float, heading: float) -> None:
        """Place the current shape rigidly with its COM at (x, y) [m] and heading [rad]."""
        pos = self.node_positions
        st = self.rigid_body_state()
        c, s = np.cos(heading - st.heading), np.sin(heading - st.heading)
        rot = np.array([[c, -s], [s, c]])
        new = (pos - st.com) @ rot.T + np.array([x, y])
        vel = self.node_velocities @ rot.T
        self.integrator.set_state(x=new, v=vel)
        self._unwrap.reset(heading)

    # ------------------------------------------------------------------ stepping
    def step(self, n_steps: int = 1) -> None:
        """Advance ``n_steps`` time steps of ``time_step``.

        Raises
        ------
        ConvergenceError
            If a step fails even after step halving.
        """
        n_steps = int(n_steps)
        if n_steps < 0:
            raise ValueError(f'n_steps = {n_steps} must be >= 0')
        self._sync_schedule(until=self.time + n_steps * self.time_step)
        dist = getattr(self, '_disturbance', None)
        if dist is None or not self._disturbance_on:
            self.integrator.advance(n_steps, self.time_step)
            return
        chunk = max(1, int(round(DISTURBANCE_INTERVAL_S / self.time_step)))
        integ = self.integrator
        while n_steps > 0:
            k = min(chunk, n_steps)
            integ.external_force[:] = torque_forces(integ.x, integ.mass, dist.advance(k * self.time_step))
            integ.advance(k, self.time_step)
            n_steps -= k

    def run(self, duration: float, record_interval: float = 0.01, progress: bool = False,
            callback=None) -> Trajectory:
        """Advance ``duration`` seconds and record samples every ``record_interval``.

        Parameters
        ----------
        duration : float
            [s] (rounded to whole steps).
        record_interval : float
            Sampling interval of the returned trajectory [s] (multiple of the step).
        progress : bool
            Show a tqdm progress bar.
        callback : callable, optional
            ``callback(sim)`` after each recorded sample.

        Returns
        -------
        Trajectory
            Includes the initial sample.
        """
        if not (np.isfinite(duration) and duration >= 0):
            raise ValueError(f'duration = {duration!r} s must be >= 0')
        n_total = int(round(duration / self.time_step))
        stride = max(1, int(round(record_interval / self.time_step)))
        samples = [self.rigid_body_state()]
        positions = [self.node_positions]
        bar = None
        if progress:
            from tqdm import tqdm
            bar = tqdm(total=n_total * self.time_step, unit='sim s', desc='frog-sim',
                       bar_format='{l_bar}{bar}| {n:.2f}/{total:.2f} sim s [{elapsed}<{remaining}]')
        done = 0
        while done < n_total:
            k = min(stride, n_total - done)
            self.step(k)
            done += k
            samples.append(self.rigid_body_state())
            positions.append(self.node_positions)
            if bar is not None:
                bar.update(k * self.time_step)
            if callback is not None:
                callback(self)
        if bar is not None:
            bar.close()
        return Trajectory.from_samples(samples, positions, self.metadata())

    def metadata(self) -> dict:
        """Parameters, profile, time step and code version (for output files)."""
        return {'params': self.params.as_dict(), 'time_step_s': self.time_step,
                'profile': {'egain_vol_pct': self.profile.egain_vol_pct,
                            'frequency_hz': self.profile.frequency_hz,
                            'coefficients': list(self.profile.coefficients),
                            'switch_time_s': self.profile.switch_time,
                            'rms_error_per_m': self.profile.rms_error},
                'gait': None if self._gait is None else {
                    'frequency_hz': self._gait[0], 'phase_offset': self._gait[1],
                    'start_s': self._gait[2], 'duration_s': self._gait[3]},
                'n_nodes': self.model.n_nodes, 'code_version': code_version('frog_sim'),
                'units': {'time': 's', 'positions': 'm', 'velocity': 'm/s', 'heading': 'rad',
                          'yaw_rate': 'rad/s'}}
