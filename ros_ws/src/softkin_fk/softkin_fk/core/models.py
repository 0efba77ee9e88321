"""Parametric soft-robot models with documented dimensions (all built on voxel grids).

Coordinates: x along the robot's length (base at x = 0), y up (the cable side of the finger),
z across the width. All dimensions in metres at the API; the tables below use millimetres.

``build_tendon_finger`` -- the 3-tendon finger of paper Fig. 12 (120 x 25 x 25 mm):

====================  =========================================================
base block            x 0-15 (vertices at x = 0 are fixed)
spine                 y 0-5, the whole length
slots (gaps)          6 slots, 5 mm wide, y 5-25, starting at x = 15, 30, 45,
                      60, 75, 90 (pitch 15 mm; rigid teeth 10 mm between them;
                      tip tooth x 95-120)
knuckles              K0 = x 15-45, K1 = x 45-75, K2 = x 75-120 (two slots each)
cable j               one per knuckle, anchored at the knuckle's distal end
                      (x = 45, 75, 120); it runs inside the spine (near the neutral
                      axis, no length change) through the proximal knuckles and
                      crosses only its own knuckle's two slots at the top edge
                      (y = 25 mm); total length L_j = anchor x (all but the two
                      slot segments is the inside portion L_R of eq. 6). The three
                      knuckles thus bend independently (a planar 3-joint finger).
tip marker ('tip')    top-right corner (120, 25, 12.5), the tracked point q
====================  =========================================================

Each cable crosses a slot as a sheet of triangles (one pair per z grid line): the cable
segment a-b across the slot plus an apex at either bottom corner of the slot (eq. 6).
Grid: cells of ``5 / resolution`` mm in x and y, ``2 * ceil(resolution / 2)`` cells across
the width.

``build_pneumatic_actuator`` -- a 3-chamber actuator in the style of Fig. 15 (48 x 48 x
136 mm scaled by ``scale``): a square column along x, base fixed at x = 0, three chambers
(radius 8 mm, at 14 mm from the axis, 120 deg apart, from x = 8 to length - 8 mm) filled with
pneumatic tetrahedra, one actuator per chamber.

``build_dea_crawler`` -- a DEA crawler strip in the style of Fig. 10: a 60 x 20 x 1 mm prism
layer; the middle 40 mm is the DEA membrane (actuation prisms), 10 mm frames (legs) at both
ends are stiff body prisms; the rear frame is fixed.

``BENDER`` geometry for ``build_tendon_finger`` -- a 240 x 25 x 25 mm single-cable actuator
with 22 slots (5 mm wide, 10 mm pitch) used by the 240-degree bending benchmark.

``build_two_material_bar`` -- the calibration specimen of Fig. 7: a 100 x 10 x 10 mm bar,
material A from x = 0 to L1, material B beyond; x = 0 fixed, the free end is a handle.
"""
from __future__ import annotations

import math

import numpy as np

from .mesh import Actuator, ElementGroup, SoftMesh
from .meshing import extrude_prisms, grid_triangles, voxel_tets

MM = 1e-3

#: finger geometry (mm), see module docstring
FINGER = dict(length=120.0, height=25.0, width=25.0, base=15.0, spine=5.0, slot_width=5.0,
              slot_starts=(15.0, 30.0, 45.0, 60.0, 75.0, 90.0), knuckle_starts=(15.0, 45.0, 75.0),
              anchors=(45.0, 75.0, 120.0), cable_heights=(25.0, 25.0, 25.0))

#: Cable triangles weigh area x (this fraction of the z spacing) x 5.0 in eq. 9. A thin sheet
#: keeps them about ten times stiffer than the spine they bend -- enough to meet eq. 6 within
#: ~1 % of the slot length (exactly with ``enforce_constraints``) -- while keeping the normal
#: equations well conditioned (full-thickness sheets slow the solver down by >10x).
CABLE_SHEET_FRACTION = 0.003

#: default finger resolution, chosen by the mesh-convergence study (``softkin convergence``,
#: pulls 3/3/3 mm): the tip moves 1.50 mm from resolution 1 (1152 tets) to the finest mesh
#: (resolution 4, 36864 tets), 0.09 mm at resolution 2 (4608 tets) and 0.11 mm at 3 -- below
#: the IK threshold of 0.2 mm -- while an iteration costs 4x less than at resolution 3.
DEFAULT_FINGER_RESOLUTION = 2


#: a single-cable bender for the 240-degree benchmark: 240 x 25 x 25 mm, 22 slots of 5 mm
#: at a 10 mm pitch from x = 15 mm, one cable along the top edge anchored at the tip
BENDER = dict(length=240.0, height=25.0, width=25.0, base=15.0, spine=5.0, slot_width=5.0,
              slot_starts=tuple(15.0 + 10.0 * i for i in range(22)), knuckle_starts=(15.0,),
              anchors=(240.0,), cable_heights=(25.0,))


def build_tendon_finger(resolution: int = DEFAULT_FINGER_RESOLUTION, shape_parameter: float = 1.0,
                        max_slot_closure: float = 0.85, geometry: dict = None,
                        width_cells: int = None) -> SoftMesh:
    """The 3-tendon finger of Fig. 12 as a tetrahedral mesh with three cable actuators.

    Parameters
    ----------
    resolution : int
        Cells per 5 mm in x and y (h = 5 / resolution mm); >= 1.
    shape_parameter : float
        R_w of the body (single material).
    max_slot_closure : float
        Fraction of a cable's slot length it may take up at most; sets the lower bound of each
        cable's shortening ratio s_j = 1 - max_slot_closure * sum(l_i) / L_j.
    geometry : dict, optional
        Dimensions (mm) in the form of :data:`FINGER` (default) or :data:`BENDER`.
    width_cells : int, optional
        Cells across the width (even; default 2 ceil(resolution / 2)).

    Returns
    -------
    SoftMesh
        Groups ``'body'`` and ``'cable_0'``..``'cable_2'``; actuators ``cable_0``..``cable_2``
        (ratios s_j, 1 = rest); marker ``'tip'``; ``info['dimensions_mm']``.

    Raises
    ------
    ValueError
        If ``resolution`` is not a positive integer.
    """
    if int(resolution) != resolution or resolution < 1:
        raise ValueError(f"resolution {resolution!r} must be a positive integer (cells per 5 mm)")
    r = int(resolution)
    f = FINGER if geometry is None else geometry
    h = 5.0 / r
    nx, ny = int(round(f['length'] / h)), int(round(f['height'] / h))
    nz = 2 * math.ceil(r / 2) if width_cells is None else int(width_cells)
    if nz < 2 or nz % 2:
        raise ValueError(f"width_cells {width_cells} must be an even number >= 2")
    hz = f['width'] / nz
    xc = (np.arange(nx) + 0.5) * h
    yc = (np.arange(ny) + 0.5) * h
    keep = np.ones((nx, ny), bool)
    for s0 in f['slot_starts']:
        in_slot = (xc > s0) & (xc < s0 + f['slot_width'])
        keep[np.ix_(in_slot, yc > f['spine'])] = False
    mask = np.repeat(keep[:, :, None], nz, axis=2)
    # anisotropic grid: build on unit cells, then scale
    verts, tets, _, gidx = voxel_tets(mask, 1.0, mirror_z_from=nz // 2)
    verts = verts * np.array([h, h, hz]) * MM
    groups = [ElementGroup('body', 'body', tets, shape_parameter=shape_parameter)]
    actuators = []
    js = int(round(f['spine'] / h))
    for c, (start, anchor, yc_mm) in enumerate(zip(f['knuckle_starts'], f['anchors'], f['cable_heights'])):
        jy = int(round(yc_mm / h))
        tris = []
        for s0 in f['slot_starts']:
            if not start <= s0 < anchor:
                continue
            i0, i1 = int(round(s0 / h)), int(round((s0 + f['slot_width']) / h))
            for kz in range(nz + 1):
                a, b = gidx[i0, jy, kz], gidx[i1, jy, kz]
                for apex in (gidx[i0, js, kz], gidx[i1, js, kz]):
                    tris.append([a, b, apex])
        tris = np.array(tris, np.int64)
        assert np.all(tris >= 0)
        name = f'cable_{c}'
        groups.append(ElementGroup(name, 'cable', tris, thickness=CABLE_SHEET_FRACTION * hz * MM))
        n_slots = sum(1 for s0 in f['slot_starts'] if start <= s0 < anchor)
        gap = n_slots * f['slot_width']
        s_min = 1.0 - max_slot_closure * gap / anchor
        actuators.append(Actuator(name, name, total_length=anchor * MM, bounds=(s_min, 1.0),
                                  segment_multiplicity=2 * (nz + 1)))
    fixed = gidx[0].ravel()
    fixed = fixed[fixed >= 0]
    tip = gidx[nx, ny, nz // 2]
    mesh = SoftMesh(verts, groups, fixed=fixed, actuators=actuators, markers={'tip': int(tip)},
                    info={'model': 'tendon_finger', 'resolution': r, 'dimensions_mm': dict(f),
                          'cell_mm': (h, h, hz)})
    return mesh


def finger_cable_pull(mesh: SoftMesh, ratios) -> np.ndarray:
    """Cable pull lengths (m), shape (3,), for shortening ratios s_j: (1 - s_j) L_j."""
    L = np.array([a.total_length for a in mesh.actuators])
    return (1.0 - np.asarray(ratios, float)) * L


def finger_ratios_from_pull(mesh: SoftMesh, pull) -> np.ndarray:
    """Shortening ratios s_j for cable pull lengths (m): s_j = 1 - pull_j / L_j."""
    L = np.array([a.total_length for a in mesh.actuators])
    return 1.0 - np.asarray(pull, float) / L


def build_pneumatic_actuator(resolution: float = 1.0, scale: float = 1.0, n_chambers: int = 3,
                             shape_parameter: float = 1.0, length_mm: float = 136.0,
                             max_ratio: float = 4.0, side_mm: float = 48.0, chamber_radius_mm: float = 8.0,
                             chamber_offset_mm: float = 14.0) -> SoftMesh:
    """A multi-chamber pneumatic actuator (Fig. 15 style), tetrahedral.

    Parameters
    ----------
    resolution : float
        Cells per 8 mm (h = 8 / resolution mm, times ``scale``); 1 gives ~3.7k tetrahedra,
        2.3 about 46k.
    scale : float
        Uniform size factor on the 48 x 48 x ``length_mm`` mm design.
    n_chambers : int
        Number of chambers (1-3), 120 deg apart; chamber 0 lies towards +y.
    shape_parameter : float
        R_w of the body.
    length_mm : float
        Length along x (mm, before scaling).
    max_ratio : float
        Upper bound of each chamber's volume ratio alpha.
    side_mm, chamber_radius_mm, chamber_offset_mm : float
        Square cross-section side, chamber radius and chamber distance from the axis (mm).

    Returns
    -------
    SoftMesh
        Groups ``'body'``, ``'chamber_0'``..; actuators ``chamber_0``..; marker ``'tip'``
        (centre of the free end face).
    """
    if not resolution > 0:
        raise ValueError(f"resolution {resolution!r} must be positive")
    if not 1 <= n_chambers <= 3:
        raise ValueError(f"n_chambers {n_chambers} must be 1, 2 or 3")
    h = 8.0 / resolution
    side, radius, offset, cap = side_mm, chamber_radius_mm, chamber_offset_mm, 8.0
    nx, ny = int(round(length_mm / h)), int(round(side / h))
    xc = (np.arange(nx) + 0.5) * h
    yc = (np.arange(ny) + 0.5) * h - ny * h / 2  # dimensions snap to the grid
    X, Y, Z = np.meshgrid(xc, yc, yc, indexing='ij')
    mask = np.ones((nx, ny, ny), bool)
    half = ny * h / 2 * MM * scale
    verts, tets, cell, gidx = voxel_tets(mask, h * MM * scale, origin=(0.0, -half, -half))
    chamber_of_cell = np.full(mask.shape, -1)
    for c in range(n_chambers):
        ang = 2 * math.pi * c / 3  # chamber 0 towards +y
        cy, cz = offset * math.cos(ang), offset * math.sin(ang)
        inside = ((Y - cy) ** 2 + (Z - cz) ** 2 <= radius ** 2) & (X > cap) & (X < length_mm - cap)
        chamber_of_cell[inside] = c
    ch = chamber_of_cell[cell[:, 0], cell[:, 1], cell[:, 2]]
    groups = [ElementGroup('body', 'body', tets[ch < 0], shape_parameter=shape_parameter)]
    actuators = []
    for c in range(n_chambers):
        name = f'chamber_{c}'
        groups.append(ElementGroup(name, 'pneumatic', tets[ch == c]))
        actuators.append(Actuator(name, name, bounds=(0.2, max_ratio)))
    fixed = gidx[0].ravel()
    fixed = fixed[fixed >= 0]
    tip = gidx[nx, ny // 2, ny // 2]
    return SoftMesh(verts, groups, fixed=fixed, actuators=actuators, markers={'tip': int(tip)},
                    info={'model': 'pneumatic_actuator', 'resolution': resolution, 'scale': scale,
                          'dimensions_mm': dict(side=side, length=length_mm, chamber_radius=radius,
                                                chamber_offset=offset, cap=cap)})


def build_dea_crawler(resolution: int = 1, thickness_mm: float = 1.0, frame_shape_parameter: float = 1.0,
                      membrane_shape_parameter: float = 0.5, max_ratio: float = 2.0) -> SoftMesh:
    """A DEA crawler strip (Fig. 10 style) of prisms.

    Parameters
    ----------
    resolution : int
        Cells per 5 mm in the plane (h = 5 / resolution mm).
    thickness_mm : float
        Layer thickness (mm).
    frame_shape_parameter, membrane_shape_parameter : float
        R_w of the stiff frames (legs) and of the passive membrane edge rows.
    max_ratio : float
        Upper bound of the DEA area ratio lambda.

    Returns
    -------
    SoftMesh
        Groups ``'frames'``, ``'membrane_edges'`` and ``'dea'``; actuator ``dea``;
        marker ``'tip'`` (front frame's front-middle vertex, top layer).
    """
    h = 5.0 / resolution
    length, width, frame = 60.0, 20.0, 10.0
    nx, ny = int(round(length / h)), int(round(width / h))
    pts, tris = grid_triangles(nx, ny, h * MM)
    verts, prisms = extrude_prisms(pts, tris, thickness_mm * MM)
    cen = pts[tris].mean(axis=1) / MM
    is_frame = (cen[:, 0] < frame) | (cen[:, 0] > length - frame)
    is_edge = ~is_frame & ((cen[:, 1] < h) | (cen[:, 1] > width - h))
    is_dea = ~is_frame & ~is_edge
    groups = [ElementGroup('frames', 'body', prisms[is_frame], shape_parameter=frame_shape_parameter),
              ElementGroup('membrane_edges', 'body', prisms[is_edge], shape_parameter=membrane_shape_parameter),
              ElementGroup('dea', 'dea', prisms[is_dea])]
    fixed = np.flatnonzero(verts[:, 0] < frame * MM + 1e-12)
    npl = len(pts)
    tip2d = nx * (ny + 1) + ny // 2
    return SoftMesh(verts, groups, fixed=fixed, actuators=[Actuator('dea', 'dea', bounds=(0.3, max_ratio))],
                    markers={'tip': int(tip2d + npl)},
                    info={'model': 'dea_crawler', 'dimensions_mm': dict(length=length, width=width,
                                                                       frame=frame, thickness=thickness_mm)})


def build_two_material_bar(interface_mm: float = 50.0, shape_parameter_a: float = 1.0,
                           shape_parameter_b: float = 0.5, resolution: int = 1,
                           length_mm: float = 100.0, side_mm: float = 10.0) -> SoftMesh:
    """Two-material calibration bar (Fig. 7a): A on x < L1, B on x > L1.

    Parameters
    ----------
    interface_mm : float
        L1, distance of the interface from the fixed end (mm); snapped to the grid.
    shape_parameter_a, shape_parameter_b : float
        R_w of materials A and B.
    resolution : int
        Cells per 5 mm (h = 5 / resolution mm).
    length_mm, side_mm : float
        Bar length and square cross-section side (mm).

    Returns
    -------
    SoftMesh
        Groups ``'A'`` and ``'B'``; fixed: both end faces (x = 0 fixed, x = L is the handle,
        its positions are given to the solver); markers ``'interface'`` (a vertex on the
        interface axis) and ``'end'``; ``info['interface_vertices']``, ``info['end_vertices']``.
    """
    h = 5.0 / resolution
    nx, ny = int(round(length_mm / h)), int(round(side_mm / h))
    i1 = int(round(interface_mm / h))
    if not 0 < i1 < nx:
        raise ValueError(f"interface at {interface_mm} mm must lie strictly inside the bar (0, {length_mm}) mm")
    mask = np.ones((nx, ny, ny), bool)
    verts, tets, cell, gidx = voxel_tets(mask, h * MM)
    in_a = cell[:, 0] < i1
    groups = [ElementGroup('A', 'body', tets[in_a], shape_parameter=shape_parameter_a),
              ElementGroup('B', 'body', tets[~in_a], shape_parameter=shape_parameter_b)]
    start = gidx[0].ravel()
    end = gidx[nx].ravel()
    iface = gidx[i1].ravel()
    mesh = SoftMesh(verts, groups, fixed=np.concatenate([start, end]),
                    markers={'interface': int(gidx[i1, ny // 2, ny // 2]), 'end': int(gidx[nx, ny // 2, ny // 2])},
                    info={'model': 'two_material_bar', 'interface_m': i1 * h * MM, 'length_m': nx * h * MM,
                          'interface_vertices': iface, 'end_vertices': end, 'start_vertices': start})
    return mesh
