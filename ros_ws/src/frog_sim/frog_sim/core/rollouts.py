"""Batched rollouts of the DER simulator for a planner decision.

The planner's ``transitions: simulator`` mode (DESIGN.md, "Planning modes") asks the
simulator itself what each primitive sequence does from the robot's estimated state.

* **Start state** (:meth:`Rollouts.estimated_start`): what a real robot can know. The
  tracked pose (x, y, yaw) and body twist (u forward, v left, w yaw rate; REP-103), and
  when each limb was last fired. The model's reference shape is placed at that pose with
  the rigid velocity field of that twist (paper eq. 13, as ``FrogSimulation.set_pose`` /
  ``set_velocity`` and the motion library do); each limb is bent to the natural curvature
  the actuation model (eq. 9) gives at the time since its firing, so a limb still relaxing
  after a kick is simulated as relaxing, not as a fresh stroke. The shape is then placed so
  that its centre of mass and eq. 11 heading are exactly the given pose.
  :meth:`Rollouts.start_from_simulation` takes a simulator's full state instead (to measure
  what the estimate loses).
* **Rollouts** (:meth:`Rollouts.rollout_batch`): each sequence of primitives, one per
  period, from that start. Sequences share prefixes: depth 2 runs the 9 first periods once
  and the 81 second periods from their end states; within a period the primitives that
  fire the same front limbs (A/B, C/E/G, D/F/H) share the steps before the rear limbs fire.
  Each such stretch of a branch is a job; the jobs whose parents are done run in one
  compiled call per thread (:func:`_run_jobs`, GIL released, jobs taken from an atomic
  counter), each thread on its own prebuilt simulator reset by copying arrays: no Python
  copies per branch. The step is the integrator's own :func:`run_direct`, so a rollout is
  the trajectory ``FrogSimulation.step`` computes with the same steps.
* **Step plan** (:meth:`Rollouts.step_plan`): the kick is where the time step matters; the
  coast after it is smooth. A period is stepped with ``kick_time_step`` (default the
  simulator's 2 ms) until ``kick_window`` after the last firing, then with steps of at most
  ``coast_time_step``. ``bench/planner_rollouts.py`` measures the error of the plan against
  the uniform 2 ms reference and the speed.

Results use the layout of the motion library's transitions (``motion_library.py``,
``docs/motion_library_format.md``): per period end, the displacement (dx, dy) [m] and the
heading change dyaw [rad] in the start pose's body frame, and the body twist u, v [m/s],
w [rad/s] at that time (eq. 10-12).

numba's cache checks only this file for :func:`_run_jobs`: after editing a kernel it calls
(integrator, element sets, energies, fluid, actuation), delete
``frog_sim/core/__pycache__/*.nb[ic]``.
"""
from __future__ import annotations

import itertools
import math
import os
from collections import namedtuple
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace

import numpy as np
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic

from .integrator import STATUS_OK, run_direct
from .model_parameters import FrogParameters
from .rigid_body import center_of_mass, heading_angle, nodal_velocities, yaw_rate
from frog_common.primitives import LIMB_IDS, LIMB_NAMES, PRIMITIVE_NAMES, primitive_limbs, primitive_name
from .simulation import DEFAULT_TIME_STEP, DISTURBANCE_INTERVAL_S, FrogSimulation
from .yaw_disturbance import TANK_YAW_TORQUE_TAU_S, torque_forces, torque_forces_into
from frog_common.se2 import wrap_angle

__all__ = ['Rollouts', 'RolloutStart', 'RolloutResult', 'tree_rows']

#: Newton force tolerance of the rollouts [N]: 100x the simulator's 1e-6 N, ~0.5 fewer
#: Newton iterations per step; it moves 1.43 s end poses by < 0.01 mm and < 0.1 deg
#: (bench/planner_rollouts.py).
ROLLOUT_FORCE_TOLERANCE = 1e-4
#: Longest coast step [s]; with the kick window below the end poses stay within ~0.2 mm
#: and ~0.1 deg of uniform 2 ms steps (bench/planner_rollouts.py).
COAST_TIME_STEP = 0.012
#: Fine steps from each firing on for this long [s]: the stroke (~0.1 s) and the fast part
#: of the recovery (eq. 9 de-actuation midpoint ~0.38 s after the firing).
KICK_WINDOW = 0.4
#: Firing times a job holds per limb: its last firing before the period and the period's own.
_FIRINGS_PER_LIMB = 2
_N_LIMBS = len(LIMB_NAMES)
#: Job key of the shared first steps of a period: the sequence before it and the front limbs
_FrontGroup = namedtuple('_FrontGroup', 'prefix front_limbs')


@dataclass
class RolloutStart:
    """The full simulator state a rollout starts from; the start is t = 0 of its clock.

    Attributes
    ----------
    x, v : ndarray, shape (2N,)
        Node positions [m] and velocities [m/s] (x0, y0, x1, ...), world frame.
    v_old : ndarray, shape (2N,)
        Velocity of the step before (the integrator's predictor; ``v`` for a fresh state).
    last_firing : ndarray, shape (4,)
        Time of each limb's last firing [s] (FL, FR, BL, BR; <= 0, -inf if never).
    pose : ndarray, shape (3,)
        Centre of mass x, y [m] and heading [rad] (eq. 10-11) of this state.
    twist : ndarray, shape (3,), optional
        Body twist u, v [m/s], w [rad/s] (eq. 10-12; set on period ends).
    yaw_torque : float
        Expected yaw torque about the COM at t = 0 [N m] (the tank's disturbance as estimated;
        it decays with ``Rollouts.yaw_torque_tau``); 0: none.
    """

    x: np.ndarray
    v: np.ndarray
    v_old: np.ndarray
    last_firing: np.ndarray
    pose: np.ndarray
    twist: np.ndarray | None = None
    yaw_torque: float = 0.0
    # the LU factors at the end of a parent period, so a child continues as one run would
    lu_packed: np.ndarray | None = field(default=None, repr=False)
    lu_valid: int = field(default=0, repr=False)
    lu_time_step: float = field(default=0.0, repr=False)


@dataclass
class RolloutResult:
    """Period ends of a batch of primitive sequences.

    Attributes
    ----------
    sequences : list of tuple of str
        The sequences, as primitive names.
    transitions : ndarray, shape (B, D, 6)
        For sequence b at the end of its period k: dx, dy [m], dyaw [rad] in the start
        pose's body frame and u, v [m/s], w [rad/s] in the body frame then (motion-library
        layout); NaN past a sequence's length or where it did not converge.
    pose : ndarray, shape (B, D, 3)
        The same ends as world poses x, y [m], heading [rad] (unwrapped from the start's).
    converged : ndarray of bool, shape (B,)
    ends : dict
        Prefix (tuple of names) -> :class:`RolloutStart` at the end of its last period: the
        full state (node positions ...), with that end as t = 0 (a start to continue from).
    lead_end : RolloutStart or None
        :meth:`Rollouts.decision_tree`: where the coast before the decision ended (the
        sequences' start; its pose and twist in the world frame).
    stats : dict
        Jobs (simulated stretches), steps, Newton iterations, LU factorisations, fallbacks
        (jobs redone with step halving), failed (jobs that did not converge).
    """

    sequences: list
    transitions: np.ndarray
    pose: np.ndarray
    converged: np.ndarray
    ends: dict = field(default_factory=dict)
    stats: dict = field(default_factory=dict)
    lead_end: RolloutStart | None = None


@intrinsic
def _next_job(typingctx, counter):
    """Atomically ``counter[0] += 1``; returns the old value (the job this thread takes)."""
    if not (isinstance(counter, types.Array) and counter.dtype == types.int64 and counter.ndim == 1):
        return None

    def codegen(context, builder, sig, args):
        ary = context.make_array(sig.args[0])(context, builder, args[0])
        ptr = cgutils.get_item_pointer(context, builder, sig.args[0], ary, [context.get_constant(types.intp, 0)])
        return builder.atomic_rmw('add', ptr, context.get_constant(types.int64, 1), 'seq_cst')
    return types.int64(counter), codegen


@njit(nogil=True, cache=True, error_model='numpy')
def _run_jobs(counter, system, solver, work, state, f_ext, mass, torque0, torque1, inv_tau, start_x, start_v,
              start_vold, start_packed, start_lu, job_start, job_t0, job_times, job_offsets, seg_n, seg_h, out_x,
              out_v, out_vold, out_packed, out_lu, out_status, out_counts):
    """Run jobs (one period of one branch each) with the integrator's :func:`run_direct`.

    Called by every rollout thread at once, each with its own ``system``, ``work`` and
    ``state`` (its live arrays, actuation and LU values, are overwritten per job); the GIL
    is released. The threads take the next job from ``counter`` (shared, atomic) until all
    are done, so uneven jobs (a coasting I against a kicking B) balance themselves.

    Job j starts from start state ``job_start[j]`` (x, v, v_old (S, 2N); LU factors
    ``start_packed`` and ``start_lu`` = (valid, step) of the run it continues) at time
    ``job_t0[j]``, with the firing times ``job_times[j]`` (limb l owns
    ``[job_offsets[j, l]:job_offsets[j, l + 1]]``) and the steps ``seg_n[j, g]`` of
    ``seg_h[j, g]`` [s] (segments with n = 0 are unused). The LU factors are kept across
    segments of equal step and refactorised when the step changes, as
    ``ImplicitEulerIntegrator.advance`` does. Writes the end state, ``out_status[j]`` (0
    or the failing step's status) and ``out_counts[j]`` = (steps, Newton iterations,
    factorisations). A yaw torque ``torque0 exp(-t inv_tau) + torque1 exp(t inv_tau)`` [N m]
    about the COM (``t`` on the jobs' clock) acts as ``FrogSimulation`` applies its
    disturbance: nodal forces (``f_ext``, this thread's) recomputed on the current shape every
    :data:`DISTURBANCE_INTERVAL_S` of a segment and held over it (here at the interval's
    mid-time value: the expected torque).
    """
    act_times = system.actuator[2]
    act_offsets = system.actuator[3]
    n_jobs = job_start.shape[0]
    while True:
        j = _next_job(counter)
        if j >= n_jobs:
            return
        for i in range(act_offsets.shape[0]):
            act_offsets[i] = job_offsets[j, i]
        for i in range(job_offsets[j, -1]):
            act_times[i] = job_times[j, i]
        s = job_start[j]
        state.x[:] = start_x[s]
        state.v[:] = start_v[s]
        state.v_old[:] = start_vold[s]
        work.packed[:] = start_packed[s]
        work.lu_state[0] = np.int64(start_lu[s, 0])
        lu_h = start_lu[s, 1]
        f_ext[:] = 0.0
        torqued = torque0 != 0.0 or torque1 != 0.0
        factorisations = work.lu_state[1]
        t = job_t0[j]
        state.time[0] = t
        status = STATUS_OK
        steps = 0
        iters = 0
        for g in range(seg_n.shape[1]):
            n = seg_n[j, g]
            if n == 0:
                continue
            h = seg_h[j, g]
            if h != lu_h:
                work.lu_state[0] = 0
            lu_h = h
            chunk = n if not torqued else max(1, int(round(DISTURBANCE_INTERVAL_S / h)))
            k = 0
            while k < n and status == STATUS_OK:
                m = min(chunk, n - k)
                if torqued:
                    tm = (t + (k + 0.5 * m) * h) * inv_tau
                    torque_forces_into(state.x, mass, torque0 * math.exp(-tm) + torque1 * math.exp(tm), f_ext)
                done, status, it, _ = run_direct(system, solver, work, state, f_ext, t + k * h, h, m, True)
                steps += done
                iters += it
                k += m
            if status != STATUS_OK:
                break
            t = t + n * h
            state.time[0] = t
        out_x[j] = state.x
        out_v[j] = state.v
        out_vold[j] = state.v_old
        out_packed[j] = work.packed
        out_lu[j, 0] = work.lu_state[0]
        out_lu[j, 1] = lu_h
        out_status[j] = status
        out_counts[j, 0] = steps
        out_counts[j, 1] = iters
        out_counts[j, 2] = work.lu_state[1] - factorisations


class Rollouts:
    """Batched rollouts of the frog simulator from an estimated state.

    Parameters
    ----------
    params : FrogParameters, optional
        The model the planner believes in (default :class:`FrogParameters`).
    library : ActuationLibrary, optional
        Fitted limb profiles (default: loaded as by :class:`FrogSimulation`).
    kick_time_step : float
        Step [s] during the kick window (default the simulator's :data:`DEFAULT_TIME_STEP`).
    coast_time_step : float
        Longest step [s] after it (default :data:`COAST_TIME_STEP`); equal to
        ``kick_time_step``: uniform steps.
    kick_window : float
        Fine steps last this long after each firing [s] (default :data:`KICK_WINDOW`).
    force_tolerance : float
        Newton residual tolerance [N] (default :data:`ROLLOUT_FORCE_TOLERANCE`).
    threads : int, optional
        Threads the jobs are spread over (default: the CPUs this process may use); one
        simulator is built per thread.
    yaw_torque_tau : float
        Time constant [s] with which a start's expected yaw torque decays (the tank's
        Ornstein-Uhlenbeck torque: its mean given the present; default
        :data:`~frog_sim.core.yaw_disturbance.TANK_YAW_TORQUE_TAU_S`).

    Examples
    --------
    >>> ro = Rollouts()                                                        # doctest: +SKIP
    >>> start = ro.estimated_start((0.1, 0.2, 0.3), (0.02, 0.0, 0.1), {'FL': -0.3})  # doctest: +SKIP
    >>> res = ro.rollout_batch(start, list(itertools.product(PRIMITIVE_NAMES, repeat=2)),
    ...                        period=1.43)                                    # doctest: +SKIP
    >>> res.transitions.shape                                                  # doctest: +SKIP
    (81, 2, 6)
    """

    def __init__(self, params: FrogParameters | None = None, *, library=None,
                 kick_time_step: float = DEFAULT_TIME_STEP, coast_time_step: float = COAST_TIME_STEP,
                 kick_window: float = KICK_WINDOW, force_tolerance: float = ROLLOUT_FORCE_TOLERANCE,
                 threads: int | None = None, yaw_torque_tau: float = TANK_YAW_TORQUE_TAU_S):
        for name, value in (('kick_time_step', kick_time_step), ('coast_time_step', coast_time_step),
                            ('force_tolerance', force_tolerance)):
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f'{name} = {value!r} must be a positive number')
        if coast_time_step < kick_time_step:
            raise ValueError(f'coast_time_step = {coast_time_step!r} s must be >= kick_time_step = '
                             f'{kick_time_step!r} s')
        if not (np.isfinite(kick_window) and kick_window >= 0):
            raise ValueError(f'kick_window = {kick_window!r} s must be >= 0')
        if not (yaw_torque_tau > 0):
            raise ValueError(f'yaw_torque_tau = {yaw_torque_tau!r} s must be > 0 (inf: held)')
        if threads is None:
            threads = len(os.sched_getaffinity(0)) if hasattr(os, 'sched_getaffinity') else os.cpu_count() or 1
        threads = int(threads)
        if not 1 <= threads <= 64:
            raise ValueError(f'threads = {threads} must be in 1-64')
        self.kick_time_step = float(kick_time_step)
        self.coast_time_step = float(coast_time_step)
        self.kick_window = float(kick_window)
        self.threads = threads
        self.yaw_torque_tau = float(yaw_torque_tau)
        first = FrogSimulation(params, library=library, force_tolerance=force_tolerance)
        # one simulator per thread: its live arrays are that thread's scratch (+ one for the
        # Python fallback of a job whose fast step failed)
        self._sims = [first] + [FrogSimulation(first.params, library=first.library,
                                               force_tolerance=force_tolerance) for _ in range(threads)]
        self.params = first.params
        self.model = first.model
        capacity = _N_LIMBS * _FIRINGS_PER_LIMB
        for sim in self._sims[:threads]:
            act = sim.integrator.actuator
            act.activation_times = np.zeros(capacity)           # written in place by _run_jobs
            act.activation_offsets = np.zeros(_N_LIMBS + 1, dtype=np.int64)
        integ = [sim.integrator for sim in self._sims[:threads]]
        # the integrator's packed numba arguments, one set per thread (same kernels as step)
        self._systems = tuple(i._system() for i in integ)
        self._works = tuple(i._work for i in integ)
        self._states = tuple(i._state for i in integ)
        self._solver = integ[0]._solver()
        self._forces = tuple(np.zeros(first.integrator.x.size) for _ in range(threads))   # per thread
        self._mass = np.ascontiguousarray(first.integrator.mass, dtype=float)
        self._packed_size = first.integrator._work.packed.size
        self._pool = ThreadPoolExecutor(threads, thread_name_prefix='frog-rollouts') if threads > 1 else None

    def close(self) -> None:
        """Stop the worker threads (also on leaving a ``with`` block)."""
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None

    def __enter__(self) -> 'Rollouts':
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # ------------------------------------------------------------------ the robot
    def set_limb_strength(self, strength=None) -> None:
        """The limb strengths the rollouts believe in (``FrogSimulation.set_limb_strength``: limb
        name -> kick factor, missing = 1; None: the nominal robot), for the start shapes too."""
        for sim in self._sims:
            sim.set_limb_strength(strength)

    @property
    def limb_strength(self) -> dict:
        """Kick strength factor of each limb the rollouts use (1 = nominal)."""
        return self._sims[0].limb_strength

    # ------------------------------------------------------------------ start states
    def estimated_start(self, pose, twist, last_fired=None, now: float = 0.0, yaw_torque: float = 0.0) -> RolloutStart:
        """The start state from what the robot knows: pose, body twist and limb firings.

        Parameters
        ----------
        pose : array_like, shape (3,)
            Tracked x, y [m] (the centre of mass, eq. 10) and yaw [rad] (eq. 11), world frame.
        twist : array_like, shape (3,)
            Body twist: forward u, lateral v (left) [m/s], yaw rate w [rad/s] (REP-103).
        last_fired : mapping, optional
            Limb name ('FL', 'FR', 'BL', 'BR') or id 0-3 -> time of its last firing [s] on
            the clock of ``now`` (a sequence: its latest element). Missing limbs are relaxed.
        now : float
            Time of the decision on that clock [s].
        yaw_torque : float
            The tank's yaw torque on the robot now, as estimated [N m] (decays with
            ``yaw_torque_tau`` through the rollouts); 0: none.

        Returns
        -------
        RolloutStart
            Reference shape, limbs bent to the eq. 9 curvature at their time since firing,
            COM and heading at ``pose``, rigid velocity field of ``twist`` (eq. 13).

        Raises
        ------
        ValueError
            For a non-finite pose, twist or time, an unknown limb, or a firing after ``now``.
        """
        pose = _finite_vector(pose, 'pose', 3)
        twist = _finite_vector(twist, 'twist', 3)
        if not np.isfinite(now):
            raise ValueError(f'now = {now!r} s must be finite')
        if not np.isfinite(yaw_torque):
            raise ValueError(f'yaw_torque = {yaw_torque!r} N m must be finite')
        last = self._last_firing(last_fired, now)
        shape = self.limb_shape(last)
        mass = self.model.mass
        rel = shape - center_of_mass(shape, mass)
        turn = pose[2] - heading_angle(shape, self.model.reference_pose, mass)
        c, s = math.cos(turn), math.sin(turn)
        positions = rel @ np.array([[c, s], [-s, c]]) + pose[:2]
        ch, sh = math.cos(pose[2]), math.sin(pose[2])
        com_velocity = np.array([ch * twist[0] - sh * twist[1], sh * twist[0] + ch * twist[1]])
        velocities = nodal_velocities(positions, mass, com_velocity, twist[2])
        v = velocities.ravel()
        return RolloutStart(x=positions.ravel(), v=v, v_old=v.copy(), last_firing=last, pose=pose.copy(),
                            twist=twist.copy(), yaw_torque=float(yaw_torque))

    def limb_shape(self, last_firing) -> np.ndarray:
        """The reference shape with each limb at rest at its eq. 9 curvature at t = 0.

        Parameters
        ----------
        last_firing : array_like, shape (4,)
            Each limb's last firing time [s] (<= 0; -inf: relaxed).

        Returns
        -------
        ndarray, shape (N, 2)
            Node positions in the reference frame [m]: the body ring as in
            ``model.reference_pose``; each limb the polygon from its corner whose edges have
            their rest lengths and whose bends (the root bend included) their natural turning
            angles ``2 atan(kappa0 dl / 2)`` at t = 0 (zero elastic energy in the limb).
        """
        model = self.model
        net = model.network
        integ = self._sims[-1].integrator          # scratch: the actuation writes kappa0 at t = 0
        integ.actuator.set_activation_times([[t] if np.isfinite(t) else [] for t in last_firing])
        integ.update_actuation(0.0)
        kappa0 = integ.kappa0
        shape = model.reference_pose.copy()
        for limb in LIMB_NAMES:
            bends = [model.root_bends[limb], *model.limb_bends[limb]]
            a, b, _ = net.bends[bends[0]]
            angle = math.atan2(*(shape[b] - shape[a])[::-1])
            point = shape[b]
            for node, edge, bend in zip(model.limb_nodes[limb], model.limb_edges[limb], bends):
                angle += 2.0 * math.atan(0.5 * kappa0[bend] * net.bend_length[bend])
                point = point + net.edge_rest_length[edge] * np.array([math.cos(angle), math.sin(angle)])
                shape[node] = point
        return shape

    def start_from_simulation(self, sim: FrogSimulation) -> RolloutStart:
        """The full state of a running simulator as a start (its time becomes t = 0).

        Node positions, velocities, the predictor's previous velocity and the limbs' last
        firings (of its schedule, up to now) are taken as they are; its limb strengths and
        kick variability are not (the rollouts use the nominal model).
        """
        integ = sim.integrator
        last = np.full(_N_LIMBS, -np.inf)
        for limb, t in sim.last_firings().items():
            last[LIMB_IDS[limb]] = t - sim.time
        st = sim.rigid_body_state()
        return RolloutStart(x=integ.x.copy(), v=integ.v.copy(), v_old=integ._state.v_old.copy(),
                            last_firing=last, pose=np.array([*st.com, st.heading]),
                            twist=np.array([*st.body_velocity, st.yaw_rate]))

    def _last_firing(self, last_fired, now) -> np.ndarray:
        last = np.full(_N_LIMBS, -np.inf)
        for key, times in dict(last_fired or {}).items():
            if isinstance(key, (int, np.integer)) and not isinstance(key, bool) and 0 <= key < _N_LIMBS:
                lid = int(key)
            elif key in LIMB_IDS:
                lid = LIMB_IDS[key]
            else:
                raise ValueError(f'limb {key!r} is unknown; expected one of {LIMB_NAMES} or an id 0-3')
            times = np.atleast_1d(np.asarray(times, dtype=float))
            if times.size == 0:
                continue
            if not np.all(np.isfinite(times)):
                raise ValueError(f'firing times of limb {LIMB_NAMES[lid]} = {times.tolist()} must be finite')
            t = float(times.max()) - float(now)
            if t > 0:
                raise ValueError(f'limb {LIMB_NAMES[lid]} fired at {float(times.max())!r} s, after now = '
                                 f'{now!r} s; give firings up to the decision time')
            last[lid] = t
        return last

    # ------------------------------------------------------------------ step plan
    def period_steps(self, start: float, period: float, latest_firing: float) -> list[tuple[int, float]]:
        """Steps of one period: ``[(n, h), ...]`` from ``start`` [s] for ``period`` [s].

        ``kick_time_step`` until ``kick_window`` after ``latest_firing`` (the last firing
        of any limb up to the period's end, [s]; -inf: none), then equal steps of at most
        ``coast_time_step`` to the period's end. A step that divides its span within 1e-9
        is used as it is (so a uniform plan is what ``FrogSimulation(time_step=h)`` does).
        """
        fine, coarse = self.kick_time_step, self.coast_time_step
        kick = min(max(latest_firing + self.kick_window - start, 0.0), period) if np.isfinite(latest_firing) else 0.0
        n1 = _whole_steps(kick, fine) if kick > 0 else 0
        if n1 * fine >= period - 1e-9 or fine == coarse:
            n = _whole_steps(period, fine)
            return [(n, _even_step(period, n, fine))]
        rest = period - n1 * fine
        n2 = _whole_steps(rest, coarse)
        plan = [(n1, fine)] if n1 else []
        return plan + [(n2, _even_step(rest, n2, coarse))]

    def step_plan(self, start: RolloutStart, sequence, period: float) -> list[list[tuple[int, float]]]:
        """The steps :meth:`rollout_batch` takes for ``sequence``: per period ``[(n, h), ...]``.

        A period whose primitive fires front limbs is stepped in two parts, split before the
        rear limbs fire (``pulse_duration`` later): the first part is shared by the
        primitives with the same front limbs (A/B, C/E/G, D/F/H) and simulated once. Driving
        ``FrogSimulation.step`` with these segments (``time_step = h``; ``step(n)``) takes
        the same steps.
        """
        return [segments for segments, _, _ in self._periods(start, tuple(primitive_name(p) for p in sequence),
                                                              float(period))]

    def _periods(self, start, seq, period):
        """Per period of ``seq``: (segments, shared front segments, firings {limb id: t})."""
        pulse = self.params.pulse_duration
        last = start.last_firing.copy()
        out = []
        for k, prim in enumerate(seq):
            t0 = k * period
            front, rear = primitive_limbs(prim)
            fired = {LIMB_IDS[l]: t0 for l in front}
            fired.update({LIMB_IDS[l]: t0 + pulse for l in rear})
            for lid, t in fired.items():
                last[lid] = t
            latest = float(np.max(last))
            segments = self.period_steps(t0, period, latest)
            shared = 0
            if front:
                # the steps that end before the rear limbs fire (``pulse`` after the front; at a
                # step ending on the firing the kernel already sees it) are the same for every
                # primitive with these front limbs, whether it fires rear limbs or not
                n, h = segments[0]
                shared = math.ceil((pulse - 1e-9) / h) - 1
                if 1 <= shared < n:
                    segments = [(shared, h), (n - shared, h)] + segments[1:]
                else:
                    shared = 0
            out.append((segments, shared, dict(fired)))
        return out

    # ------------------------------------------------------------------ rollouts
    def rollout_batch(self, start: RolloutStart, sequences, period: float | None = None) -> RolloutResult:
        """Simulate each primitive sequence from ``start``, one primitive per ``period``.

        Parameters
        ----------
        start : RolloutStart
            From :meth:`estimated_start` or :meth:`start_from_simulation`.
        sequences : sequence of sequences of primitives
            Ids 0-8 or names 'A'-'I' (e.g. the 81 pairs of a depth-2 tree, or a beam);
            sequences sharing a prefix share its simulation, and the primitives of a period
            that fire the same front limbs share the steps before the rear limbs fire.
        period : float, optional
            Primitive period T [s] (default ``params.primitive_period``), in (0, 5].

        Returns
        -------
        RolloutResult
            ``transitions[b, k]`` at the end of period k of sequence b.

        Raises
        ------
        ValueError
            For an empty batch or sequence, an unknown primitive, or a period that is not in
            (0, 5] s.
        """
        period = self.params.primitive_period if period is None else period
        if not (isinstance(period, (int, float, np.floating, np.integer)) and np.isfinite(period)
                and 0 < period <= 5.0):
            raise ValueError(f'period = {period!r} s must be in (0, 5]')
        period = float(period)
        seqs = _normalise(sequences)
        depth = max(len(s) for s in seqs)
        # the job graph: a job is one stretch of one branch; key -> (parent key, wave, t0,
        # firing times per limb, segments). Wave 2k: period k up to the rear firing (or all
        # of it); wave 2k + 1: the rest of period k.
        jobs = {}
        for seq in seqs:
            parent = ()
            times = [[t] if np.isfinite(t) else [] for t in start.last_firing]
            for k, (segments, shared, fired) in enumerate(self._periods(start, seq, period)):
                t0 = k * period
                before = [list(t[-1:]) for t in times]        # each limb's last firing before t0
                now = [b + ([fired[lid]] if lid in fired else []) for lid, b in enumerate(before)]
                key = seq[:k + 1]
                if shared:
                    front = tuple(sorted(lid for lid, t in fired.items() if t == t0))
                    group = _FrontGroup(seq[:k], front)
                    # the rear firing lies after every step of the shared part: leave it out
                    early = [b + ([fired[lid]] if lid in front else []) for lid, b in enumerate(before)]
                    jobs.setdefault(group, (parent, 2 * k, t0, early, segments[:1]))
                    h = segments[0][1]
                    jobs.setdefault(key, (group, 2 * k + 1, t0 + shared * h, now, segments[1:]))
                else:
                    jobs.setdefault(key, (parent, 2 * k, t0, now, segments))
                parent, times = key, now
        done = {(): start}
        stats = {'jobs': 0, 'steps': 0, 'newton_iterations': 0, 'factorisations': 0, 'fallbacks': 0,
                 'failed': 0}
        for wave in range(2 * depth):
            batch = [(key, job) for key, job in jobs.items() if job[1] == wave and job[0] in done]
            if batch:
                for (key, _), end in zip(batch, self._run_wave([job for _, job in batch], done, stats,
                                                               (start.yaw_torque, 0.0))):
                    if end is not None:
                        done[key] = end
        transitions = np.full((len(seqs), depth, 6), np.nan)
        poses = np.full((len(seqs), depth, 3), np.nan)
        converged = np.zeros(len(seqs), dtype=bool)
        c, s = math.cos(start.pose[2]), math.sin(start.pose[2])
        to_body = np.array([[c, s], [-s, c]])
        for b, seq in enumerate(seqs):
            converged[b] = seq in done
            for k in range(len(seq)):
                end = done.get(seq[:k + 1])
                if end is None:
                    break
                poses[b, k] = end.pose
                transitions[b, k, :2] = to_body @ (end.pose[:2] - start.pose[:2])
                transitions[b, k, 2] = end.pose[2] - start.pose[2]
                transitions[b, k, 3:] = end.twist
        # the jobs run on the decision's clock; an end handed out is its own t = 0
        ends = {key: replace(end, last_firing=end.last_firing - len(key) * period,
                             yaw_torque=start.yaw_torque * self._decay(len(key) * period))
                for key, end in done.items() if key and not isinstance(key, _FrontGroup)}
        return RolloutResult(sequences=seqs, transitions=transitions, pose=poses, converged=converged, ends=ends,
                             stats=stats)

    def decision_tree(self, start: RolloutStart, period: float, depth: int = 1, lead: float = 0.0,
                      first_primitives=(), from_lead_end: bool = False) -> tuple[np.ndarray, RolloutResult]:
        """A planner decision's tree: coast ``lead`` [s] from ``start`` (nothing fired, limbs
        relaxing: where the robot will be when the decision fires), then every sequence of
        ``depth`` primitives, one per ``period`` (only those starting with one of
        ``first_primitives``, if given: a beam).

        Returns
        -------
        rows : ndarray, shape (P + ... + P^depth, 6)
            :func:`tree_rows` from ``start.pose`` (before the lead; with ``from_lead_end`` from
            the coast's end, where the decision is executed): what the planner chains by eq. 18
            (frog_planner ``tree_from_rows``), NaN where not simulated.
        result : RolloutResult
            The rollouts after the lead.

        Raises
        ------
        ValueError
            For a bad period, lead or primitive, or a lead coast that did not converge.
        """
        if not (np.isfinite(lead) and 0.0 <= lead <= 5.0):
            raise ValueError(f'lead = {lead!r} s must be in [0, 5]')
        if not 1 <= int(depth) <= 5:
            raise ValueError(f'depth = {depth!r} must be in 1-5')
        firsts = {primitive_name(p) for p in first_primitives}
        origin = start.pose
        if lead > 0:
            start = self.rollout_batch(start, [('I',)], period=float(lead)).ends.get(('I',))
            if start is None:
                raise ValueError(f'the {lead:.3f} s coast before the decision did not converge')
        seqs = [s for s in itertools.product(PRIMITIVE_NAMES, repeat=int(depth)) if not firsts or s[0] in firsts]
        result = self.rollout_batch(start, seqs, period=period)
        result.lead_end = start
        return tree_rows(result, start.pose if from_lead_end else origin, int(depth)), result

    def run_firings(self, start: RolloutStart, firings, duration: float,
                    yaw_torque_end: float | None = None) -> RolloutStart | None:
        """Simulate ``duration`` [s] from ``start`` with limbs fired at given times (not a primitive
        schedule: what a robot actually fired, e.g. from ``frog/bridge/sent``).

        Parameters
        ----------
        firings : mapping
            Limb name or id -> firing time [s] in [0, duration] on the start's clock (at most one
            per limb).
        yaw_torque_end : float, optional
            The yaw torque at the end [N m]: the torque then follows the Ornstein-Uhlenbeck
            bridge's mean from ``start.yaw_torque`` to it (what a filter that knows both
            assumes); None: the start's torque decays.

        Returns
        -------
        RolloutStart or None
            The end state (its time ``duration``; firing times on the start's clock), or None
            if the step did not converge.
        """
        if not (np.isfinite(duration) and 0.0 < duration <= 5.0):
            raise ValueError(f'duration = {duration!r} s must be in (0, 5]')
        times = [[t] if np.isfinite(t) else [] for t in start.last_firing]
        for key, t in dict(firings).items():
            lid = key if isinstance(key, (int, np.integer)) and 0 <= key < _N_LIMBS else LIMB_IDS.get(key)
            if lid is None:
                raise ValueError(f'limb {key!r} is unknown; expected one of {LIMB_NAMES} or an id 0-3')
            if not (np.isfinite(t) and 0.0 <= t <= duration):
                raise ValueError(f'limb {LIMB_NAMES[lid]} fired at {t!r} s, outside [0, {duration}] s')
            times[int(lid)] = times[int(lid)][-1:] + [float(t)]
        latest = max((ts[-1] for ts in times if ts), default=-np.inf)
        stats = {'jobs': 0, 'steps': 0, 'newton_iterations': 0, 'factorisations': 0, 'fallbacks': 0, 'failed': 0}
        job = ((), 0, 0.0, times, self.period_steps(0.0, float(duration), latest))
        n0 = start.yaw_torque
        if yaw_torque_end is None:
            torque, n1 = (n0, 0.0), n0 * self._decay(duration)
        else:
            torque, n1 = self._bridge(n0, float(yaw_torque_end), float(duration)), float(yaw_torque_end)
        end = self._run_wave([job], {(): start}, stats, torque)[0]
        return None if end is None else replace(end, yaw_torque=n1)

    def _bridge(self, n0: float, n1: float, span: float) -> tuple[float, float]:
        """(A, B) with ``A exp(-t / tau) + B exp(t / tau)`` the mean of the OU torque given ``n0``
        at 0 and ``n1`` at ``span`` (``[n0 sinh((T - t)/tau) + n1 sinh(t/tau)] / sinh(T/tau)``);
        constant ``n0`` when it does not decay."""
        if math.isinf(self.yaw_torque_tau):
            return n0, 0.0
        e = math.exp(span / self.yaw_torque_tau)
        two_sinh = e - 1.0 / e
        return (n0 * e - n1) / two_sinh, (n1 - n0 / e) / two_sinh

    def _decay(self, t: float) -> float:
        """The expected yaw torque's factor after ``t`` [s]."""
        return math.exp(-t / self.yaw_torque_tau)



    def _run_wave(self, batch, done, stats, torque=(0.0, 0.0)):
        """Jobs whose parents are done, in one :func:`_run_jobs` call per thread; their ends.
        ``torque``: (A, B) of the yaw torque ``A exp(-t / tau) + B exp(t / tau)`` [N m] on the jobs' clock."""
        n_jobs, ndof = len(batch), self._mass.size * 2
        parents = sorted({job[0] for job in batch}, key=str)
        index = {key: i for i, key in enumerate(parents)}
        starts = [done[key] for key in parents]
        capacity = _N_LIMBS * _FIRINGS_PER_LIMB
        job_start = np.array([index[job[0]] for job in batch], dtype=np.int64)
        job_t0 = np.array([job[2] for job in batch], dtype=float)
        job_times = np.zeros((n_jobs, capacity))
        job_offsets = np.zeros((n_jobs, _N_LIMBS + 1), dtype=np.int64)
        n_seg = max(len(job[4]) for job in batch)
        seg_n = np.zeros((n_jobs, n_seg), dtype=np.int64)
        seg_h = np.zeros((n_jobs, n_seg))
        for j, (_, _, _, times, segments) in enumerate(batch):
            flat = [t for limb in times for t in limb]
            job_times[j, :len(flat)] = flat
            job_offsets[j, 1:] = np.cumsum([len(limb) for limb in times])
            for g, (n, h) in enumerate(segments):
                seg_n[j, g], seg_h[j, g] = n, h
        start_x = np.array([s.x for s in starts])
        start_v = np.array([s.v for s in starts])
        start_vold = np.array([s.v_old for s in starts])
        start_packed = np.zeros((len(starts), self._packed_size))
        start_lu = np.zeros((len(starts), 2))
        for i, s in enumerate(starts):
            if s.lu_packed is not None:
                start_packed[i] = s.lu_packed
                start_lu[i] = (s.lu_valid, s.lu_time_step)
        out_x = np.empty((n_jobs, ndof))
        out_v = np.empty((n_jobs, ndof))
        out_vold = np.empty((n_jobs, ndof))
        out_packed = np.empty((n_jobs, self._packed_size))
        out_lu = np.empty((n_jobs, 2))
        out_status = np.empty(n_jobs, dtype=np.int64)
        out_counts = np.zeros((n_jobs, 3), dtype=np.int64)
        counter = np.zeros(1, dtype=np.int64)
        args = (self._mass, float(torque[0]), float(torque[1]), 1.0 / self.yaw_torque_tau, start_x, start_v,
                start_vold, start_packed, start_lu, job_start, job_t0, job_times, job_offsets, seg_n, seg_h, out_x,
                out_v, out_vold, out_packed, out_lu, out_status, out_counts)

        def run(w):
            _run_jobs(counter, self._systems[w], self._solver, self._works[w], self._states[w], self._forces[w],
                      *args)
        if self._pool is None or n_jobs == 1:
            run(0)
        else:
            for future in [self._pool.submit(run, w) for w in range(min(self.threads, n_jobs))]:
                future.result()
        ends = []
        for j, (parent, _, t0, times, segments) in enumerate(batch):
            stats['jobs'] += 1
            parent_start = done[parent]
            if out_status[j] != STATUS_OK:
                stats['fallbacks'] += 1
                if not self._fallback(parent_start, times, t0, segments, j, out_x, out_v, out_vold, out_packed,
                                      out_lu, out_counts, torque):
                    stats['failed'] += 1
                    ends.append(None)
                    continue
            stats['steps'] += int(out_counts[j, 0])
            stats['newton_iterations'] += int(out_counts[j, 1])
            stats['factorisations'] += int(out_counts[j, 2])
            pose = self._end_pose(out_x[j], parent_start.pose[2])
            last = np.array([limb[-1] if limb else -np.inf for limb in times])
            ends.append(RolloutStart(x=out_x[j].copy(), v=out_v[j].copy(), v_old=out_vold[j].copy(),
                                     last_firing=last, pose=pose, twist=self._twist(out_x[j], out_v[j], pose[2]),
                                     lu_packed=out_packed[j].copy(), lu_valid=int(out_lu[j, 0]),
                                     lu_time_step=float(out_lu[j, 1])))
        return ends

    def _fallback(self, start, times, t0, segments, j, out_x, out_v, out_vold, out_packed, out_lu,
                  out_counts, torque=(0.0, 0.0)) -> bool:
        """Redo job ``j`` with ``ImplicitEulerIntegrator.advance`` (step halving, SuperLU), as
        ``FrogSimulation.step`` would after a failed fast step; False if that fails too."""
        from .integrator import ConvergenceError
        integ = self._sims[-1].integrator
        integ.actuator.set_activation_times(times)
        integ.set_state(x=start.x, v=start.v)
        integ._state.v_old[:] = start.v_old
        integ.external_force[:] = 0.0
        if start.lu_packed is not None:
            integ._work.packed[:] = start.lu_packed
            integ._lu_state[0] = start.lu_valid
            integ._lu_h = start.lu_time_step
        integ.time = t0
        steps0, iters0, facts0 = integ.stats.steps, integ.stats.newton_iterations, integ.factorizations
        try:
            t = t0
            for n, h in segments:
                torqued = tuple(torque) != (0.0, 0.0)
                chunk = max(n, 1) if not torqued else max(1, int(round(DISTURBANCE_INTERVAL_S / h)))
                for k in range(0, n, chunk):
                    m = min(chunk, n - k)
                    if torqued:      # as _run_jobs
                        tm = t + (k + 0.5 * m) * h
                        integ.external_force[:] = torque_forces(integ.x, self._mass, torque[0] * self._decay(tm)
                                                                + torque[1] / self._decay(tm))
                    integ.advance(m, h)
                t += n * h
        except ConvergenceError:
            return False
        out_x[j], out_v[j], out_vold[j] = integ.x, integ.v, integ._state.v_old
        out_packed[j] = integ._work.packed
        out_lu[j] = (integ._lu_state[0], integ._lu_h or 0.0)
        out_counts[j] = (integ.stats.steps - steps0, integ.stats.newton_iterations - iters0,
                         integ.factorizations - facts0)
        return True

    def _end_pose(self, x, previous_heading) -> np.ndarray:
        pos = x.reshape(-1, 2)
        mass = self.model.mass
        heading = heading_angle(pos, self.model.reference_pose, mass)
        heading = previous_heading + wrap_angle(heading - previous_heading)     # a period turns < pi
        return np.array([*center_of_mass(pos, mass), heading])

    def _twist(self, x, v, heading) -> np.ndarray:
        pos, vel = x.reshape(-1, 2), v.reshape(-1, 2)
        mass = self.model.mass
        vc = center_of_mass(vel, mass)
        c, s = math.cos(heading), math.sin(heading)
        return np.array([c * vc[0] + s * vc[1], -s * vc[0] + c * vc[1], yaw_rate(pos, vel, mass)])


def tree_rows(result: RolloutResult, start_pose, depth: int, names=PRIMITIVE_NAMES) -> np.ndarray:
    """Rows of 6 level by level (P^d rows at level d, base-P order), each in its own period's start frame.

    The planner chains one period at a time (eq. 18): a row of level d is the end of period
    d (``result.ends`` of the prefix) seen from the end of period d - 1, level 1 from
    ``start_pose`` (the decision's pose, before any lead): dx, dy [m] and dyaw [rad] in that
    frame, then u, v [m/s], w [rad/s] at the end (the motion library's layout). Prefixes that
    were not simulated (outside a beam, or not converged) give NaN rows.
    """
    rows = []
    for d in range(1, depth + 1):
        for prefix in itertools.product(names, repeat=d):
            end = result.ends.get(prefix)
            parent = result.ends.get(prefix[:-1]) if d > 1 else None
            base = np.asarray(start_pose, dtype=float) if d == 1 else (parent.pose if parent else None)
            if end is None or base is None:
                rows.append(np.full(6, np.nan))
                continue
            c, s = math.cos(base[2]), math.sin(base[2])
            dx, dy = end.pose[0] - base[0], end.pose[1] - base[1]
            rows.append(np.array([c * dx + s * dy, -s * dx + c * dy, end.pose[2] - base[2], *end.twist]))
    return np.array(rows)


def _finite_vector(value, name, size) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=float).ravel()
    except (TypeError, ValueError):
        raise ValueError(f'{name} = {value!r} must be {size} numbers') from None
    if arr.shape != (size,) or not np.all(np.isfinite(arr)):
        raise ValueError(f'{name} = {value!r} must be {size} finite numbers')
    return arr


def _normalise(sequences) -> list:
    try:
        seqs = [tuple(primitive_name(p) for p in seq) for seq in sequences]
    except TypeError:
        raise ValueError(f'sequences = {sequences!r} must be a list of primitive sequences') from None
    if not seqs or any(len(s) == 0 for s in seqs):
        raise ValueError('sequences must be a non-empty list of non-empty primitive sequences')
    return seqs


def _whole_steps(span: float, step: float) -> int:
    """Fewest steps of at most ``step`` covering ``span`` (a near-integer ratio is taken as is)."""
    ratio = span / step
    n = round(ratio)
    return max(1, int(n if abs(ratio - n) < 1e-9 * max(1.0, ratio) else math.ceil(ratio)))


def _even_step(span: float, n: int, step: float) -> float:
    """``step`` if ``n`` of it make ``span`` (within 1e-9 relative), else ``span / n``."""
    return step if abs(n * step - span) <= 1e-9 * span else span / n
