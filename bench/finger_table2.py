"""Table II investigation: what moves the calibrated R_w^A / R_w^B of eq. 16.

``softkin calibrate`` gives R_w^A / R_w^B = 5.46 and 8.75 for R_m = 3.75 and 5.68, the paper
7.08 and 10.30. This script recalibrates under one change at a time and prints the ratios
beside the baseline and the paper:

* ``baseline``      -- the package's calibration (numba local step, eq. 4 with the cube root,
                       stretch 5 %, L1 = 50 mm, resolution 1, both end faces clamped, interface
                       displacement = mean over the interface cross-section);
* ``numpy``         -- the same with the plain numpy local step (the path the eq. 4 variant uses);
* ``eq4_printed``   -- eq. 4 as printed: the soft target scaled by r = Vol(V) / Vol(V^d) itself,
                       not its cube root;
* ``stretch_X``     -- end displacement X % of the length;
* ``L1_X``          -- interface at X mm;
* ``resolution_2``  -- cells of 2.5 mm;
* ``surface``       -- interface displacement read on the bar's side face (what a camera sees);
* ``free_end``      -- the pulled end face free to contract laterally: only its centre line is
                       prescribed;
* ``rwA_X``         -- R_w of material A = X instead of 1 (Table II gives only the ratio);
* combinations: ``eq4_surface``, ``eq4_stretch_20``, ``surface_L1_30``, ``surface_L1_70``,
  ``surface_res_2``.

    ./dev bench finger_table2 [variant ...]
"""
from __future__ import annotations

import inspect
import os
import sys
import time

import numpy as np

from softkin_fk.core import forward as fwd
from softkin_fk.core import local_step
from softkin_fk.core.calibration import PAPER_TABLE_II
from softkin_fk.core.forward import ForwardSolver
from softkin_fk.core.models import build_two_material_bar

RATIOS = (3.75, 5.68)
PAPER = {r: w for _, _, r, w in PAPER_TABLE_II}


def _printed_eq4_local_step():
    """local_step_numpy with eq. 4 as printed (no cube root on the volume ratio)."""
    src = inspect.getsource(local_step.local_step_numpy)
    old = "np.cbrt(rv / np.maximum(vol, 1e-3 * rv))"
    assert old in src, "local_step_numpy changed: update this script"
    ns = dict(local_step.__dict__)
    exec(compile(src.replace(old, "(rv / np.maximum(vol, 1e-3 * rv))"), "eq4_printed", "exec"), ns)
    return ns["local_step_numpy"]


def elasticity_ratio(rw_a, rw_b, interface_mm=50.0, stretch=0.05, resolution=1, use_numba=True,
                     measure="mean", free_end=False):
    """eps_B / eps_A of the simulated bar (eq. 16's right-hand side), as calibration.py computes it."""
    bar = build_two_material_bar(interface_mm, rw_a, rw_b, resolution=resolution)
    L, L1 = bar.info["length_m"], bar.info["interface_m"]
    end = bar.info["end_vertices"]
    if free_end:   # keep only the end face's centre line (z = mid) prescribed
        zmid = np.median(bar.vertices[end, 2])
        ymid = np.median(bar.vertices[end, 1])
        keep = end[(np.abs(bar.vertices[end, 2] - zmid) < 1e-9) & (np.abs(bar.vertices[end, 1] - ymid) < 1e-9)]
        bar.fixed = np.concatenate([bar.info["start_vertices"], keep])
        end = keep
    fp = bar.vertices[bar.fixed].copy()
    fp[np.isin(bar.fixed, end), 0] += stretch * L
    res = ForwardSolver(bar, use_numba=use_numba).solve(fixed_positions=fp, tol=1e-9, max_iter=20000)
    iface = bar.info["interface_vertices"]
    if measure == "surface":    # the side face z = 0 (a camera's view of the interface line)
        iface = iface[np.abs(bar.vertices[iface, 2] - bar.vertices[:, 2].min()) < 1e-12]
    dL, dL1 = stretch * L, float(np.mean(res.positions[iface, 0] - bar.vertices[iface, 0]))
    return L1 * (dL - dL1) / ((L - L1) * dL1)


def calibrate(rm, rel_tol=1e-3, rw_a=1.0, **kw):
    """R_w^A / R_w^B whose bar gives R_m, by bisection on log R_w^B (as calibration.py)."""
    lo, hi = np.log(rw_a * 1e-3), np.log(rw_a)
    mid = hi
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        r = elasticity_ratio(rw_a, float(np.exp(mid)), **kw)
        if abs(r / rm - 1) < rel_tol:
            break
        lo, hi = (mid, hi) if r > rm else (lo, mid)
    return rw_a / float(np.exp(mid))


VARIANTS = {
    "baseline": {},
    "numpy": dict(use_numba=False),
    "eq4_printed": dict(use_numba=False, _eq4=True),
    "stretch_1": dict(stretch=0.01),
    "stretch_20": dict(stretch=0.20),
    "L1_30": dict(interface_mm=30.0),
    "L1_70": dict(interface_mm=70.0),
    "resolution_2": dict(resolution=2),
    "surface": dict(measure="surface"),
    "free_end": dict(free_end=True),
    "eq4_surface": dict(use_numba=False, _eq4=True, measure="surface"),
    "eq4_stretch_20": dict(use_numba=False, _eq4=True, stretch=0.20),
    "surface_L1_30": dict(measure="surface", interface_mm=30.0),
    "surface_L1_70": dict(measure="surface", interface_mm=70.0),
    "surface_res_2": dict(measure="surface", resolution=2),
    "rwA_0.5": dict(rw_a=0.5),
    "rwA_0.2": dict(rw_a=0.2),
    "surface_rwA_0.5": dict(measure="surface", rw_a=0.5),
}


def main(argv=None) -> int:
    names = (argv if argv is not None else sys.argv[1:]) or list(VARIANTS)
    unknown = [n for n in names if n not in VARIANTS]
    if unknown:
        print(f"unknown variants {unknown}; known: {list(VARIANTS)}", file=sys.stderr)
        return 2
    print(f"load average {os.getloadavg()[0]:.2f}; paper: " + ", ".join(f"R_m {r}: {PAPER[r]}" for r in RATIOS))
    slope_paper = np.log(PAPER[RATIOS[1]] / PAPER[RATIOS[0]]) / np.log(RATIOS[1] / RATIOS[0])
    print(f"slope = d log(R_w^A / R_w^B) / d log R_m between the rows; paper {slope_paper:.2f}")
    print(f"{'variant':16s} " + " ".join(f"{'R_m ' + str(r):>10s}" for r in RATIOS) + "   ratio/paper  slope      s")
    from softkin_fk.core.calibration import uniaxial_shape_parameter_ratio
    ideal = uniaxial_shape_parameter_ratio(RATIOS)
    print(f"{'closed form':16s} " + " ".join(f"{v:10.2f}" for v in ideal) + "   "
          + " ".join(f"{v / PAPER[r]:5.2f}" for v, r in zip(ideal, RATIOS))
          + f"  {np.log(ideal[1] / ideal[0]) / np.log(RATIOS[1] / RATIOS[0]):5.2f}   (3 R_m - 1) / 2, uniaxial stress")
    printed = _printed_eq4_local_step()
    original = fwd.local_step_numpy
    for name in names:
        kw = dict(VARIANTS[name])
        eq4 = kw.pop("_eq4", False)
        fwd.local_step_numpy = printed if eq4 else original
        t0 = time.perf_counter()
        try:
            vals = [calibrate(r, **kw) for r in RATIOS]
        finally:
            fwd.local_step_numpy = original
        rel = " ".join(f"{v / PAPER[r]:5.2f}" for v, r in zip(vals, RATIOS))
        slope = np.log(vals[1] / vals[0]) / np.log(RATIOS[1] / RATIOS[0])
        print(f"{name:16s} " + " ".join(f"{v:10.2f}" for v in vals) + f"   {rel}  {slope:5.2f}  "
              f"{time.perf_counter() - t0:5.1f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
