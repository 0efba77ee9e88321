"""Drag calibration and the design / gait sweep (paper sections 2.3-2.4, Fig. 4).

Both are grids of independent gait simulations run with :func:`frog_sim.core.batch.
run_chunked` (local processes or a Dask cluster, resumable, deterministic).

Electrical energy model of one SMA pulse (for the cost of transport)
-------------------------------------------------------------------
Each limb has its own 11.1 V LiPo (paper, "Robot Electronics") switched by a MOSFET
straight onto the nitinol loop for one pulse of ``pulse`` seconds (80 ms on the
hardware). The current is set by the wire: I = V / R_wire. R_wire = 2.0 ohm is our
estimate for the loop in the authors' limbs (about 80 mm of 0.2 mm nitinol at about
1 ohm/m per 10^-6 ohm m resistivity, i.e. ~26 ohm/m, plus contacts; it gives ~5.5 A,
inside the 45C rating of a 300 mAh pack, 13.5 A). Energy per pulse
E = V^2 / R * pulse = 4.9 J. A gait cycle fires every limb once, so the input power is
P = 4 E f and the cost of transport COT = P / (m g v) with m the robot's mass (body +
limbs) and v the steady forward speed. The paper's COT of 158 at 0.4 Hz and 2.2 cm/s
implies ~4.3 J per pulse for a ~0.2 kg robot, consistent with this estimate. Only the
ranking of designs matters for the sweep and it does not depend on E (E is the same for
all designs), but the absolute numbers do.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

import numpy as np

from .core.actuation import ActuationLibrary
from .core.batch import run_chunked
from .core.model_parameters import FrogParameters
from .studies import measured_speeds, simulated_speed

GRAVITY = 9.81  # [m/s^2]


@dataclass(frozen=True)
class SmaPulseEnergy:
    """Electrical energy of one SMA heating pulse: E = V^2 / R * pulse (see module doc).

    Attributes
    ----------
    battery_voltage : float
        [V] (paper: 11.1 V 3S LiPo per limb).
    wire_resistance : float
        [ohm] nitinol loop + contacts (estimate, see module doc).
    pulse : float
        [s] heating pulse length (hardware 0.080 s).
    limbs_per_cycle : int
        Pulses per gait cycle (all four limbs fire once).
    """

    battery_voltage: float = 11.1
    wire_resistance: float = 2.0
    pulse: float = 0.080
    limbs_per_cycle: int = 4

    @property
    def current(self) -> float:
        """[A]"""
        return self.battery_voltage / self.wire_resistance

    @property
    def energy_per_pulse(self) -> float:
        """[J]"""
        return self.battery_voltage * self.current * self.pulse

    def input_power(self, frequency_hz: float) -> float:
        """Mean electrical power of a gait at ``frequency_hz`` [W]."""
        return self.limbs_per_cycle * self.energy_per_pulse * frequency_hz

    def cost_of_transport(self, frequency_hz: float, mass_kg: float, speed: float) -> float:
        """COT = P / (m g v) [-]; inf for a robot that does not move forward."""
        if speed <= 0:
            return math.inf
        return self.input_power(frequency_hz) / (mass_kg * GRAVITY * speed)


def robot_mass(params: FrogParameters) -> float:
    """Total mass [kg] of the robot model for ``params`` (body + limbs)."""
    from .core.frog_model import build_frog_model
    return float(build_frog_model(params).total_mass)


# ------------------------------------------------------------------ grids and tasks
def _speed_task(spec: dict, start: int, stop: int) -> dict:
    """Batch task: steady forward speed of gait rows ``start:stop`` of ``spec['grid']``."""
    lib = ActuationLibrary.load()
    base = FrogParameters().replace(**spec["params"])
    speeds = np.empty(stop - start)
    for i, (egain, freq, phase, cbn) in enumerate(spec["grid"][start:stop]):
        params = base.replace(egain_vol_pct=float(egain), body_drag_normal=float(cbn))
        speeds[i] = simulated_speed(float(freq), float(phase), cycles=spec["cycles"],
                                    skip_cycles=spec["skip_cycles"], params=params,
                                    time_step=spec["time_step"], library=lib)
    return {"speed": speeds}


def run_speed_grid(grid, work_dir, params: Optional[dict] = None, cycles: int = 8,
                   skip_cycles: int = 3, time_step: Optional[float] = None,
                   workers: Optional[int] = None, scheduler: Optional[str] = None,
                   progress: bool = True, desc: str = "gaits") -> np.ndarray:
    """Steady speeds [m/s] of gait rows ``(egain %, frequency Hz, phase, C_bn)``."""
    from .core.simulation import DEFAULT_TIME_STEP
    grid = [[float(v) for v in row] for row in grid]
    spec = {"grid": grid, "params": params or {}, "cycles": int(cycles),
            "skip_cycles": int(skip_cycles), "time_step": float(time_step or DEFAULT_TIME_STEP)}
    return run_chunked(_speed_task, spec, len(grid), 1, work_dir, workers=workers,
                       scheduler=scheduler, progress=progress, desc=desc)["speed"]


@dataclass
class CalibrationResult:
    """Body normal drag coefficient fitted to the calibration runs."""

    candidates: np.ndarray        # C_bn values tried [-]
    frequencies: np.ndarray       # [Hz]
    measured: np.ndarray          # measured steady speed per frequency [m/s]
    simulated: np.ndarray         # (C, F) simulated speeds [m/s]
    rms: np.ndarray               # (C,) RMS speed error [m/s]

    @property
    def best_index(self) -> int:
        return int(np.argmin(self.rms))

    @property
    def best(self) -> float:
        return float(self.candidates[self.best_index])


def calibrate_body_drag(candidates=np.round(np.arange(0.8, 2.0001, 0.1), 3), frequencies=None,
                        measured: Optional[dict] = None, work_dir="runs/calibration.chunks",
                        **grid_kwargs) -> CalibrationResult:
    """Grid search of C_bn minimising the RMS speed error (paper: search 0.8-2.0 -> 0.8).

    Parameters
    ----------
    candidates : array_like
        C_bn values to try.
    frequencies : array_like, optional
        Frequencies [Hz] (default: every calibration run that has a measured profile at
        10 % EGaIn).
    measured : dict, optional
        ``{frequency: speed}`` [m/s]; default: the mean of the two recordings of the
        calibration file (see ``studies.measured_speeds``).
    """
    if measured is None:
        meas = measured_speeds()
        measured = {f: float(np.nanmean(list(v.values()))) for f, v in meas.items()}
    lib = ActuationLibrary.load()
    available = set(np.round(lib.frequencies(10.0), 3))
    if frequencies is None:
        frequencies = sorted(f for f in measured if round(f, 3) in available)
    frequencies = np.asarray(frequencies, dtype=float)
    candidates = np.asarray(candidates, dtype=float)
    grid = [(10.0, f, 0.5, c) for c in candidates for f in frequencies]
    speeds = run_speed_grid(grid, work_dir, desc="calibration", **grid_kwargs)
    sim = speeds.reshape(len(candidates), len(frequencies))
    meas = np.array([measured[f] for f in frequencies])
    rms = np.sqrt(np.mean((sim - meas) ** 2, axis=1))
    return CalibrationResult(candidates, frequencies, meas, sim, rms)


def sweep_grid(phases=np.round(np.arange(0.0, 0.95, 0.1), 2), egains=None) -> list[tuple]:
    """Every measured (EGaIn, frequency) pair x every phase offset (paper Fig. 4)."""
    lib = ActuationLibrary.load()
    egains = egains if egains is not None else sorted({e for e, _ in lib.profiles})
    return [(e, f, p) for e in egains for f in lib.frequencies(e) for p in phases]


def design_sweep(work_dir="runs/sweep.chunks", phases=None, egains=None,
                 energy: SmaPulseEnergy = SmaPulseEnergy(), body_drag_normal: Optional[float] = None,
                 **grid_kwargs) -> list[dict]:
    """Steady speed and COT of every design/gait; rows sorted like the grid."""
    grid = sweep_grid(**({} if phases is None else {"phases": phases}),
                      egains=egains)
    cbn = FrogParameters().body_drag_normal if body_drag_normal is None else body_drag_normal
    speeds = run_speed_grid([(e, f, p, cbn) for e, f, p in grid], work_dir, desc="sweep",
                            **grid_kwargs)
    masses = {e: robot_mass(FrogParameters().replace(egain_vol_pct=e)) for e, _, _ in grid}
    rows = []
    for (e, f, p), v in zip(grid, speeds):
        rows.append({"egain_vol_pct": e, "frequency_hz": f, "phase_offset": p,
                     "speed_m_per_s": float(v), "mass_kg": masses[e],
                     "input_power_w": energy.input_power(f),
                     "cost_of_transport": energy.cost_of_transport(f, masses[e], float(v))})
    return rows
