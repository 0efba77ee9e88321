"""Small synthetic motion libraries in the file format of docs/motion_library_format.md.

The tests build their own libraries (frog_sim writes the real one). Transitions come from a
plain kinematic model, integrated here with small Euler steps: each primitive drives the
body velocities towards its own (forward speed, yaw rate) with time constant ``TAU``.
"""

import json

import numpy as np

NAMES = np.array(list("ABCDEFGHI"))
BITS = np.array(["1100", "1111", "0111", "1011", "0110", "1001", "0100", "1000", "0000"])
# (forward speed m/s, lateral speed m/s, yaw rate rad/s) each primitive drives towards.
TARGETS = np.array([[0.030, 0.0, 0.0], [0.040, 0.0, 0.0], [0.015, 0.0, 0.35], [0.015, 0.0, -0.35],
                    [0.020, 0.0, 0.15], [0.020, 0.0, -0.15], [0.005, 0.0, 0.5], [0.005, 0.0, -0.5],
                    [0.0, 0.0, 0.0]])
TAU = 0.8  # s


def sample_initial_states(n_states, seed=0):
    """Uniform initial body velocities in the paper's ranges (m/s, m/s, rad/s), shape (N, 3)."""
    rng = np.random.default_rng(seed)
    return np.column_stack([rng.uniform(0.0, 0.04, n_states), rng.uniform(-0.03, 0.03, n_states),
                            rng.uniform(-np.pi / 6, np.pi / 6, n_states)])


def kinematic_transitions(initial_states, times, targets=TARGETS, substeps=10):
    """Transitions (P, N, T, 6) of the kinematic model, start body frame; velocities in the body frame."""
    n_prim, n_states = len(targets), len(initial_states)
    out = np.zeros((n_prim, n_states, len(times), 6))
    dt = (times[1] - times[0]) / substeps
    for p in range(n_prim):
        x = np.zeros(n_states)
        y = np.zeros(n_states)
        th = np.zeros(n_states)
        vel = np.array(initial_states, dtype=float)
        out[p, :, 0, 3:] = vel
        for t in range(1, len(times)):
            for _ in range(substeps):
                x += dt * (np.cos(th) * vel[:, 0] - np.sin(th) * vel[:, 1])
                y += dt * (np.sin(th) * vel[:, 0] + np.cos(th) * vel[:, 1])
                th += dt * vel[:, 2]
                vel += dt * (targets[p] - vel) / TAU
            out[p, :, t] = np.column_stack([x, y, th, vel])
    return out


def library_arrays(n_states=40, horizon=3.0, sample_interval=0.05, seed=0, n_primitives=9):
    """A complete, valid library as a dict of arrays (keys of the file format)."""
    times = np.round(np.arange(0.0, horizon + 0.5 * sample_interval, sample_interval), 12)
    init = sample_initial_states(n_states, seed)
    trans = kinematic_transitions(init, times, TARGETS[:n_primitives])
    metadata = {"units": {"initial_states": ["m/s", "m/s", "rad/s"],
                          "transitions": ["m", "m", "rad", "m/s", "m/s", "rad/s"], "times": "s"},
                "horizon_s": horizon, "sample_interval_s": sample_interval,
                "sampling": {"seed": seed, "distribution": "uniform"}, "code_version": "test synthetic"}
    return {
        "format": np.array("frog-motion-library", dtype="<U32"),
        "format_version": np.array(1, dtype=np.int64),
        "primitive_names": NAMES[:n_primitives].astype("<U1"),
        "primitive_bits": BITS[:n_primitives].astype("<U4"),
        "state_names": np.array(["forward_velocity", "lateral_velocity", "yaw_rate"], dtype="<U16"),
        "initial_states": init,
        "times": times,
        "transition_names": np.array(["x", "y", "heading", "forward_velocity", "lateral_velocity", "yaw_rate"],
                                     dtype="<U16"),
        "transitions": trans.astype(np.float32),
        "converged": np.ones((n_primitives, n_states), dtype=bool),
        "metadata": np.array(json.dumps(metadata)),
    }


def write_library(path, arrays=None, **kwargs):
    """Write ``arrays`` (default: ``library_arrays(**kwargs)``) as an uncompressed .npz; returns the path."""
    arrays = library_arrays(**kwargs) if arrays is None else arrays
    with open(path, "wb") as fh:
        np.savez(fh, **arrays)
    return path
