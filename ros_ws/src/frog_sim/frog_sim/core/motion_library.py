"""Motion-primitive library: every primitive simulated from many initial body velocities.

Paper: seed 000, "Data Collection Using the DER Simulation" and Fig. S2. For N initial
states sampled uniformly over (forward, lateral, yaw rate) body velocities, each of the
nine primitives is simulated from the rest shape moving rigidly with that velocity
(eq. 13), and the rigid-body state (eq. 10-12) is stored at regular times along the
whole horizon, in the body frame of the start pose. The file layout is the contract in
``docs/motion_library_format.md``, written and read by ``frog_common.motion_library_file``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import numpy as np

from frog_common.motion_library_file import write_motion_library
from frog_common.primitives import PRIMITIVE_BITS, PRIMITIVE_NAMES
from frog_common.version import code_version

from .batch import run_chunked, spec_hash
from .model_parameters import FrogParameters

__all__ = ["LibrarySpec", "sample_initial_states", "simulate_transitions", "generate_library"]



@dataclass
class LibrarySpec:
    """What a library is made of (all SI). Defaults: paper / authors' data.

    Attributes
    ----------
    n_states : int
        Number of sampled initial states N (paper: 8503).
    horizon : float
        Simulated time per transition [s] (authors' data 3.0; up to 5).
    sample_interval : float
        Spacing of the stored samples [s]; the planner's period must be a multiple.
    seed : int
        Seed of the uniform sampling (numpy default_rng).
    forward_range, lateral_range : (float, float)
        Initial body velocity ranges [m/s] (0..4 cm/s forward, -3..3 cm/s lateral).
    yaw_rate_range : (float, float)
        Initial yaw rate range [rad/s] (-30..30 deg/s).
    params : dict
        FrogParameters overrides (e.g. ``{"egain_vol_pct": 10.0}``).
    time_step : float, optional
        Integrator step [s] (default: the simulator's default).
    mirror : bool
        Exploit the robot's left-right symmetry: states are drawn in antithetic pairs
        (s, mirror(s)) -- each still uniform over the symmetric box -- and the transitions of
        mirror(s) are the mirrored transitions of s under the mirrored primitive (C<->D,
        E<->F, G<->H), so half of the simulations are exact reflections. Halves the cost;
        switch off for a model that is not mirror-symmetric.
    """

    n_states: int = 200
    horizon: float = 3.0
    sample_interval: float = 0.05
    seed: int = 0
    forward_range: tuple = (0.0, 0.04)
    lateral_range: tuple = (-0.03, 0.03)
    yaw_rate_range: tuple = (-np.deg2rad(30.0), np.deg2rad(30.0))
    params: Optional[dict] = None
    time_step: Optional[float] = None
    mirror: bool = True

    def validate(self) -> None:
        if self.n_states < 1:
            raise ValueError(f"n_states = {self.n_states} must be >= 1")
        if not 0 < self.horizon <= 5.0:
            raise ValueError(f"horizon = {self.horizon} s must be in (0, 5]")
        steps = self.horizon / self.sample_interval
        if not (self.sample_interval > 0 and abs(steps - round(steps)) < 1e-9):
            raise ValueError(f"sample_interval = {self.sample_interval} s must divide the horizon "
                             f"{self.horizon} s")
        for name in ("forward_range", "lateral_range", "yaw_rate_range"):
            lo, hi = getattr(self, name)
            if not lo <= hi:
                raise ValueError(f"{name} = {(lo, hi)} must be (low, high) with low <= high")

    def as_json(self) -> dict:
        from .simulation import DEFAULT_TIME_STEP
        return {"n_states": int(self.n_states), "horizon_s": float(self.horizon),
                "sample_interval_s": float(self.sample_interval), "seed": int(self.seed),
                "forward_velocity_range": [float(v) for v in self.forward_range],
                "lateral_velocity_range": [float(v) for v in self.lateral_range],
                "yaw_rate_range": [float(v) for v in self.yaw_rate_range],
                "params": FrogParameters().replace(**(self.params or {})).as_dict(),
                "time_step_s": float(self.time_step or DEFAULT_TIME_STEP),
                "mirror_pairs": bool(self.mirror)}


def sample_initial_states(spec: LibrarySpec) -> np.ndarray:
    """Uniform samples, shape (N, 3): forward [m/s], lateral [m/s], yaw rate [rad/s].

    With ``spec.mirror`` rows 2i and 2i+1 are a state and its mirror image (lateral
    velocity and yaw rate negated); the ranges must then be symmetric about zero.
    """
    rng = np.random.default_rng(spec.seed)
    lo = np.array([spec.forward_range[0], spec.lateral_range[0], spec.yaw_rate_range[0]])
    hi = np.array([spec.forward_range[1], spec.lateral_range[1], spec.yaw_rate_range[1]])
    if not spec.mirror:
        return lo + (hi - lo) * rng.random((spec.n_states, 3))
    if not (np.isclose(lo[1], -hi[1]) and np.isclose(lo[2], -hi[2])):
        raise ValueError("mirror pairs need lateral and yaw-rate ranges symmetric about 0, got "
                         f"{spec.lateral_range} and {spec.yaw_rate_range}")
    base = lo + (hi - lo) * rng.random(((spec.n_states + 1) // 2, 3))
    pairs = np.stack([base, base * MIRROR_STATE], axis=1).reshape(-1, 3)
    return pairs[:spec.n_states]


#: Sign flips of a state / transition row under the mirror y -> -y.
MIRROR_STATE = np.array([1.0, -1.0, -1.0])
MIRROR_TRANSITION = np.array([1.0, -1.0, -1.0, 1.0, -1.0, -1.0])


def mirror_primitive_index() -> np.ndarray:
    """Index of each primitive's mirror image: swap FR<->FL and BL<->BR in its bits."""
    bits = [PRIMITIVE_BITS[n] for n in PRIMITIVE_NAMES]
    mirrored = [b[1] + b[0] + b[3] + b[2] for b in bits]
    return np.array([bits.index(m) for m in mirrored])


_SIMULATORS: dict = {}


def _simulator(spec_json: dict):
    """One simulator per worker process and spec (model build and numba warm-up once)."""
    from .simulation import FrogSimulation
    key = spec_hash(spec_json)
    if key not in _SIMULATORS:
        _SIMULATORS.clear()
        params = FrogParameters().replace(**spec_json["params"])
        _SIMULATORS[key] = FrogSimulation(params, time_step=spec_json["time_step_s"])
    return _SIMULATORS[key]


def simulate_transitions(sim, initial_state, horizon: float, sample_interval: float,
                         primitives=PRIMITIVE_NAMES) -> tuple[np.ndarray, np.ndarray]:
    """Simulate each primitive from the rest shape moving with ``initial_state``.

    Parameters
    ----------
    sim : FrogSimulation
        Reused: reset before each transition.
    initial_state : array_like, shape (3,)
        Forward [m/s], lateral [m/s] body velocity and yaw rate [rad/s] at t = 0 (eq. 13).
    horizon, sample_interval : float
        [s]

    Returns
    -------
    transitions : ndarray, shape (P, T, 6)
        x, y [m], heading [rad] in the start pose's body frame; forward, lateral [m/s]
        and yaw rate [rad/s] in the body frame at that time (eq. 10-12).
    converged : ndarray of bool, shape (P,)
    """
    from .simulation import ConvergenceError
    n_samples = int(round(horizon / sample_interval)) + 1
    stride = int(round(sample_interval / sim.time_step))
    if abs(stride * sim.time_step - sample_interval) > 1e-9:
        raise ValueError(f"sample_interval {sample_interval} s is not a multiple of the time "
                         f"step {sim.time_step} s")
    out = np.full((len(primitives), n_samples, 6), np.nan)
    ok = np.zeros(len(primitives), dtype=bool)
    forward, lateral, yaw_rate = (float(v) for v in initial_state)
    for p, prim in enumerate(primitives):
        sim.reset()
        sim.set_velocity(forward, lateral, yaw_rate, frame="body")
        start = sim.rigid_body_state()
        c, s = np.cos(start.heading), np.sin(start.heading)
        to_body = np.array([[c, s], [-s, c]])   # R(-heading0)
        sim.execute_primitive(prim, start=0.0)
        try:
            for k in range(n_samples):
                if k:
                    sim.step(stride)
                st = sim.rigid_body_state()
                out[p, k, :2] = to_body @ (st.com - start.com)
                out[p, k, 2] = st.heading - start.heading
                out[p, k, 3:5] = st.body_velocity
                out[p, k, 5] = st.yaw_rate
            ok[p] = True
        except ConvergenceError:
            out[p] = np.nan
    return out, ok


def _library_task(spec_json: dict, start: int, stop: int) -> dict:
    """Batch task: transitions of simulated states ``start:stop`` (see batch.run_chunked).

    Without mirror pairs item i is state i; with them item i is the pair (2i, 2i+1) and
    the second row is the exact reflection of the first (see :class:`LibrarySpec`).
    """
    sim = _simulator(spec_json)
    states = np.asarray(spec_json["initial_states"])
    mirror = spec_json.get("mirror_pairs", False)
    n_samples = int(round(spec_json["horizon_s"] / spec_json["sample_interval_s"])) + 1
    rows = 2 if mirror else 1
    trans = np.empty((stop - start, rows, len(PRIMITIVE_NAMES), n_samples, 6), dtype=np.float32)
    conv = np.empty((stop - start, rows, len(PRIMITIVE_NAMES)), dtype=bool)
    perm = mirror_primitive_index()
    for i, item in enumerate(range(start, stop)):
        state = states[rows * item]
        t, ok = simulate_transitions(sim, state, spec_json["horizon_s"],
                                     spec_json["sample_interval_s"])
        trans[i, 0], conv[i, 0] = t.astype(np.float32), ok
        if mirror:
            trans[i, 1] = (t[perm] * MIRROR_TRANSITION).astype(np.float32)
            conv[i, 1] = ok[perm]
    return {"transitions": trans, "converged": conv}


def generate_library(spec: LibrarySpec, out_path, work_dir=None, workers: Optional[int] = None,
                     scheduler: Optional[str] = None, progress: bool = True,
                     chunk_size: int = 25) -> Path:
    """Simulate the library and write it (atomically) to ``out_path``.

    Chunks go to ``work_dir`` (default ``<out_path>.chunks``) so an interrupted run resumes;
    the result is bit-identical for any ``workers`` / ``scheduler``.

    Returns
    -------
    Path
        ``out_path``.
    """
    spec.validate()
    out_path = Path(out_path)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    states = sample_initial_states(spec)
    spec_json = spec.as_json()
    task_spec = dict(spec_json, initial_states=states)
    work = Path(work_dir) if work_dir else out_path.with_name(out_path.name + ".chunks")
    t0 = time.perf_counter()
    n_items = (spec.n_states + 1) // 2 if spec.mirror else spec.n_states
    arrays = run_chunked(_library_task, task_spec, n_items, chunk_size, work,
                         workers=workers, scheduler=scheduler, progress=progress,
                         desc="library states (mirror pairs)" if spec.mirror else "library states")
    elapsed = time.perf_counter() - t0
    p, t = len(PRIMITIVE_NAMES), arrays["transitions"].shape[-2]
    per_state = arrays["transitions"].reshape(-1, p, t, 6)[:spec.n_states]
    transitions = np.ascontiguousarray(per_state.transpose(1, 0, 2, 3))
    converged = np.ascontiguousarray(arrays["converged"].reshape(-1, p)[:spec.n_states].T)
    times = np.arange(transitions.shape[2]) * spec.sample_interval
    robot = spec_json["params"]
    metadata = {
        "units": {"initial_states": ["m/s", "m/s", "rad/s"],
                  "transitions": ["m", "m", "rad", "m/s", "m/s", "rad/s"], "times": "s"},
        "horizon_s": spec.horizon, "sample_interval_s": spec.sample_interval,
        "sampling": {"seed": spec.seed, "distribution": "uniform",
                     "mirror_pairs": spec.mirror,
                     "simulated_transitions": n_items * len(PRIMITIVE_NAMES),
                     "forward_velocity_range": spec_json["forward_velocity_range"],
                     "lateral_velocity_range": spec_json["lateral_velocity_range"],
                     "yaw_rate_range": spec_json["yaw_rate_range"]},
        "robot": robot,
        "robot_hash": spec_hash({"robot": robot, "time_step_s": spec_json["time_step_s"]}),
        "actuation": {"pulse_duration_s": robot.get("pulse_duration"),
                      "profile": _simulator(spec_json).metadata().get("profile")},
        "time_step_s": spec_json["time_step_s"],
        "code_version": code_version("frog_sim"),
        "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "generation_wall_time_s": elapsed,
    }
    write_motion_library(out_path, states, times, transitions, converged, metadata)
    return out_path

