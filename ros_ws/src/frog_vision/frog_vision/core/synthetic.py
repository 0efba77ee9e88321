"""Synthetic swimming for rendered test sequences (no simulator needed).

Body velocities follow the frog's strokes as frog_sim's simulator produces them (measured
on its response to primitives: the front pair, then the rear pair 80 ms later, each raise
the forward speed by ~1 cm/s within ~0.1 s, peak acceleration ~0.1 m/s^2, and the speed
decays with a ~1.5 s drag time constant, so successive strokes build up 2-4 cm/s as in the
paper's calibration runs). Every second stroke is a turning one that adds a yaw-rate pulse
of up to ``turn_rate`` (the authors' library spans +-30 deg/s). The limbs curl during a
kick.
Poses are integrated exactly from the body twist at a fine step and sampled at the
camera's capture times.
"""
from __future__ import annotations

import dataclasses

import numpy as np
from frog_common.se2 import twist_arc


@dataclasses.dataclass(frozen=True)
class Trajectory:
    """Ground truth at capture times.

    Attributes
    ----------
    t : ndarray (N,)
        [s]
    pose : ndarray (N, 3)
        Body frame x, y [m], heading [rad] (continuous).
    twist : ndarray (N, 3)
        Forward, lateral [m/s], yaw rate [rad/s] (body frame).
    limb_curl : ndarray (N,)
        Limb curvature [1/m] for the outline.
    """

    t: np.ndarray
    pose: np.ndarray
    twist: np.ndarray
    limb_curl: np.ndarray


def swim_and_turn(duration: float = 10.0, fps: float = 30.0, start=(-0.05, -0.15, 0.6),
                  period: float = 1.5, kick_speed: float = 0.02, turn_rate: float = np.radians(20),
                  seed: int = 0) -> Trajectory:
    """A frog swimming forward and turning left and right (see the module docstring)."""
    rng = np.random.default_rng(seed)
    dt = 1e-3
    n = int(round(duration / dt)) + 1
    tt = np.arange(n) * dt
    fwd = np.zeros(n)
    lat = np.zeros(n)
    yaw = np.zeros(n)
    curl = np.zeros(n)
    tau_rise, tau_decay = 0.05, 1.5

    def pulse(t0):
        s = np.clip(tt - t0, 0, None)
        return np.where(tt >= t0, np.exp(-s / tau_decay) - np.exp(-s / tau_rise), 0) / 0.91   # peak ~1

    for k, t0 in enumerate(np.arange(0.3, duration, period)):
        kind = k % 4                         # forward, left, forward, right
        amp = kick_speed * rng.uniform(0.8, 1.2)
        both = 0.5 * (pulse(t0) + pulse(t0 + 0.08))      # front pair, rear pair one pulse later
        fwd += amp * both
        lat += 0.1 * amp * both * rng.uniform(-1, 1)
        if kind in (1, 3):
            turn = np.clip(tt - t0, 0, None)
            shape = np.where(tt >= t0, np.exp(-turn / 0.6) - np.exp(-turn / 0.12), 0) / 0.56
            yaw += (1 if kind == 1 else -1) * turn_rate * rng.uniform(0.6, 1.0) * shape
        s = tt - t0
        curl += np.where((s >= 0) & (s < 0.3), 40.0 * np.sin(np.pi * np.clip(s, 0, 0.3) / 0.3), 0)
    pose = np.zeros((n, 3))
    pose[0] = start
    for i in range(1, n):
        pose[i] = \
            twist_arc(pose[i - 1], ((fwd[i - 1] + fwd[i]) / 2, (lat[i - 1] + lat[i]) / 2,
                                          (yaw[i - 1] + yaw[i]) / 2), dt)
    idx = np.round(np.arange(0, duration, 1.0 / fps) / dt).astype(int)
    return Trajectory(tt[idx], pose[idx], np.column_stack([fwd, lat, yaw])[idx], curl[idx])
