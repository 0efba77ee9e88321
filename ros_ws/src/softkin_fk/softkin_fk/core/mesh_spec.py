"""User meshes: a volume mesh file plus a JSON spec sidecar -> :class:`~softkin_fk.core.mesh.SoftMesh`.

A researcher's own model (e.g. a gmsh ``.msh`` with physical groups) becomes a robot for the
solvers with :func:`load_mesh_with_spec`; :func:`export_mesh_with_spec` writes any
``SoftMesh`` (e.g. a built-in model) the other way, which also gives a spec template.

Mesh files: anything meshio reads that holds ``tetra`` (tetrahedral bodies) or ``wedge``
(prism shells) cells -- ``.msh`` (gmsh 2.2/4.1), ``.vtu``, ``.vtk``, ``.mesh`` (Medit), ... --
or a TetGen ``.node``/``.ele`` pair (an ``.ele`` region attribute counts as a physical tag).

Spec (JSON; every length in it -- coordinates, boxes, tolerances, cable lengths and
thickness -- is in the mesh file's units, converted to metres by ``units``/``scale``)::

    {
      "units": "mm",                        # m | cm | mm | um | in, or "scale": 0.001
      "default_shape_parameter": 1.0,       # R_w of volume cells no region/actuator claims
      "regions": [                          # body element groups (eq. 3-5)
        {"name": "soft", "cells": {"physical": "soft"}, "shape_parameter": 0.3}
      ],
      "fixed": [                            # union of vertex selections (the base); required
        {"box": [[-1, -1, -1], [0.001, 26, 26]]}
      ],
      "actuators": [                        # in the order of the actuation vector
        {"name": "chamber_0", "type": "pneumatic", "cells": {"physical": 2}, "bounds": [0.2, 4]},
        {"name": "membrane", "type": "dea", "cells": {"cell_set": "dea"}},
        {"name": "cable_0", "type": "cable", "total_length": 45, "bounds": [0.93, 1],
         "paths": [[[15, 25, 0], [20, 25, 0], [30, 25, 0], [35, 25, 0], [45, 25, 0]]],
         "apex_offset": [0, -20, 0]}
      ],
      "markers": {"tip": {"point": [120, 25, 12.5]}}
    }

Cell selectors (``"cells"``; a list of selectors means their union):

* ``{"physical": 3}`` or ``{"physical": "soft"}`` -- a gmsh physical group (tag, or name via
  the file's ``$PhysicalNames``); also Medit refs and TetGen region attributes;
* ``{"cell_set": "name"}`` -- a meshio cell set;
* ``{"cell_data": "field", "value": 2}`` -- cells whose integer cell-data field equals value;
* ``{"elements": [0, 5, ...]}`` -- zero-based indices among the file's cells of the needed
  type (volume cells: all tetra blocks then all wedge blocks; cables: triangles), in file order.
  A plain string or number is short for ``{"physical": ...}``.

Regions and pneumatic (tetra) / DEA (wedge) actuators take volume cells; one cell may belong
to one group only. ``fixed`` entries: ``{"box": [min, max]}``, ``{"plane": {"point": p,
"normal": n}, "tolerance": t}``, ``{"indices": [...]}`` (file vertex numbers) or a cell
selector (all vertices of those cells, e.g. a gmsh physical surface of the base). Markers:
``{"vertex": i}``, ``{"point": p}`` (nearest vertex; error beyond ``tolerance``, default 5 %
of the bounding-box diagonal) or a cell selector naming one vertex (a gmsh physical point).

Cables (eq. 6) are cable triangles ``(a, b, apex)`` with the cable running a -> b across a
gap. Give them either as triangle cells (``"cells"``, e.g. a physical group of triangles, with
``"segment_multiplicity"``: triangles per cable segment) or as polylines ``"paths"`` (one or
more parallel strands, e.g. one per grid line across the width): path points snap to the
nearest vertices, segments whose midpoint lies outside the body are the gaps l_i (or list
them with ``"gaps": [segment indices]``), and each gap gets the apexes nearest to a and b
moved by ``"apex_offset"`` (two triangles; without it one triangle on the vertex nearest to
the gap's midpoint). ``total_length`` is L of eq. 6 (gaps plus the inside portion L_R;
default: the path length); ``thickness`` the slab a triangle stands for (default 0.003 x the
median tetrahedron edge, a thin sheet as in the built-in finger). Defaults for ``bounds``:
cable (1 - 0.85 gaps / L, 1), pneumatic (0.2, 4), DEA (0.3, 2); ``null`` means unbounded.

Errors (missing tags, empty selections, no fixed vertices, ...) raise :class:`MeshSpecError`
with a message naming the problem.
"""
from __future__ import annotations

import dataclasses
import json
import os
from typing import Dict, List, Optional, Union

import numpy as np

from .mesh import (ACTUATION_WEIGHT, BODY_WEIGHT, Actuator, ElementGroup, SoftMesh, orient_tets, read_tetgen,
                   write_tetgen)

UNITS = {'m': 1.0, 'cm': 1e-2, 'mm': 1e-3, 'um': 1e-6, 'in': 0.0254}
#: tag fields looked up (in this order) for ``{"physical": ...}``
TAG_FIELDS = ('gmsh:physical', 'medit:ref', 'tetgen:region', 'CellEntityIds')
#: a cable triangle's slab thickness relative to the median tetrahedron edge (cf. models.CABLE_SHEET_FRACTION)
CABLE_SHEET_FRACTION = 0.003
MESHIO_EXTENSIONS = ('.msh', '.vtu', '.vtk', '.mesh', '.meshb', '.xdmf', '.med', '.inp', '.bdf', '.nas',
                     '.su2', '.ugrid', '.off', '.obj', '.ply', '.stl', '.h5m', '.xml', '.dat', '.tec')


class MeshSpecError(ValueError):
    """A problem with a user mesh or its spec (message names the file, key or tag)."""


@dataclasses.dataclass
class _Cells:
    """All cells of one meshio type, concatenated over blocks in file order."""

    data: np.ndarray
    fields: Dict[str, np.ndarray]  # per-cell integer data (tags)
    sets: Dict[str, np.ndarray]    # cell-set name -> indices


@dataclasses.dataclass
class _MeshFile:
    path: str
    points: np.ndarray
    cells: Dict[str, _Cells]
    names: Dict[str, tuple]  # physical name -> (tag, dim)


# --- reading ------------------------------------------------------------------------------------
def _tetgen_base(path: str) -> Optional[str]:
    root, ext = os.path.splitext(path)
    if ext in ('.node', '.ele'):
        return root
    if ext == '' and os.path.exists(path + '.node'):
        return path
    return None


def read_mesh_file(path: str) -> _MeshFile:
    """Points and cells (by type, with tags and sets) of a meshio file or a TetGen pair."""
    base = _tetgen_base(path)
    if base is not None:
        for ext in ('.node', '.ele'):
            if not os.path.exists(base + ext):
                raise MeshSpecError(f"mesh file {base + ext!r} not found (TetGen needs .node and .ele)")
        try:
            verts, tets, attr = read_tetgen(base, return_attributes=True)
        except (ValueError, IndexError) as exc:
            raise MeshSpecError(f"{base}.node/.ele: {exc}")
        fields = {} if attr is None else {'tetgen:region': attr}
        return _MeshFile(path, verts, {'tetra': _Cells(tets, fields, {})}, {})
    if not os.path.exists(path):
        raise MeshSpecError(f"mesh file {path!r} not found")
    import meshio
    try:
        m = meshio.read(path)
    except meshio.ReadError as exc:
        raise MeshSpecError(f"cannot read mesh {path!r}: {exc} (formats: meshio volume meshes such as "
                            ".msh, .vtu, .vtk, .mesh, or TetGen .node/.ele)")
    except Exception as exc:  # meshio raises assorted errors on malformed files
        raise MeshSpecError(f"cannot read mesh {path!r}: {type(exc).__name__}: {exc}")
    pts = np.asarray(m.points, float)
    if pts.shape[1] == 2:
        pts = np.column_stack([pts, np.zeros(len(pts))])
    by_type: Dict[str, list] = {}
    for b, block in enumerate(m.cells):
        by_type.setdefault(block.type, []).append(b)
    cells = {}
    for ctype, blocks in by_type.items():
        data = np.concatenate([np.asarray(m.cells[b].data, np.int64) for b in blocks])
        offsets = np.cumsum([0] + [len(m.cells[b].data) for b in blocks])
        fields = {}
        for key, per_block in m.cell_data.items():
            arrs = [np.asarray(per_block[b]) for b in blocks]
            if all(a.ndim == 1 and np.issubdtype(a.dtype, np.number) for a in arrs):
                fields[key] = np.concatenate(arrs)
        sets = {}
        for name, per_block in m.cell_sets.items():
            idx = [offsets[k] + np.asarray(per_block[b], np.int64) for k, b in enumerate(blocks)
                   if per_block[b] is not None and len(per_block[b])]
            if idx:
                sets[name] = np.concatenate(idx)
        cells[ctype] = _Cells(data, fields, sets)
    names = {str(k): (int(v[0]), int(v[1]) if len(v) > 1 else -1) for k, v in m.field_data.items()}
    return _MeshFile(path, pts, cells, names)


class _Loader:
    def __init__(self, mf: _MeshFile, spec: dict, spec_name: str):
        self.mf, self.spec, self.name = mf, spec, spec_name
        self.scale = self._scale()
        pts = mf.points
        self.diag = float(np.linalg.norm(pts.max(axis=0) - pts.min(axis=0))) if len(pts) else 0.0
        # volume cells: tetra first, then wedge (the 'elements' index space)
        self.vol_types = [t for t in ('tetra', 'wedge') if t in mf.cells and len(mf.cells[t].data)]
        if not self.vol_types:
            raise MeshSpecError(f"{mf.path}: no tetrahedra or wedges (cell types: {sorted(mf.cells)}); "
                                "softkin needs a volume mesh")
        self.vol_offset = {}
        off = 0
        for t in self.vol_types:
            self.vol_offset[t] = off
            off += len(mf.cells[t].data)
        self.n_vol = off
        self.owner = np.full(self.n_vol, '', dtype=object)  # group claiming each volume cell

    def err(self, msg):
        return MeshSpecError(f"{self.name}: {msg}")

    def _scale(self):
        sp = self.spec
        if 'scale' in sp:
            s = sp['scale']
            if not isinstance(s, (int, float)) or not s > 0:
                raise self.err(f"'scale' must be a positive number (file units to metres), got {s!r}")
            return float(s)
        u = sp.get('units', 'm')
        if u not in UNITS:
            raise self.err(f"unknown units {u!r}; use one of {sorted(UNITS)} or 'scale'")
        return UNITS[u]

    # -- cell selection -----------------------------------------------------------------------
    def _tag_value(self, value, ctype, ctx):
        if isinstance(value, str):
            if value not in self.mf.names:
                raise self.err(f"{ctx}: physical name {value!r} is not in {self.mf.path} "
                               f"(names: {sorted(self.mf.names) or 'none'})")
            return self.mf.names[value][0]
        return int(value)

    def select(self, sel, ctype: str, ctx: str) -> np.ndarray:
        """Indices (within ``ctype``'s concatenated cells) chosen by a cell selector."""
        if isinstance(sel, list):
            if not sel:
                raise self.err(f"{ctx}: empty selector list")
            return np.unique(np.concatenate([self.select(s, ctype, ctx) for s in sel]))
        if isinstance(sel, (str, int)) and not isinstance(sel, bool):
            sel = {'physical': sel}
        if not isinstance(sel, dict):
            raise self.err(f"{ctx}: a cell selector must be an object, string, number or list, got {sel!r}")
        cells = self.mf.cells.get(ctype)
        n = 0 if cells is None else len(cells.data)
        if 'physical' in sel:
            tag = self._tag_value(sel['physical'], ctype, ctx)
            field = None if cells is None else next((f for f in TAG_FIELDS if f in cells.fields), None)
            if field is None:
                raise self.err(f"{ctx}: {self.mf.path} has no physical tags on its {ctype} cells")
            idx = np.flatnonzero(cells.fields[field] == tag)
            if idx.size == 0:
                found = sorted(set(cells.fields[field].tolist()))
                raise self.err(f"{ctx}: physical tag {sel['physical']!r} (= {tag}) not found among the "
                               f"{ctype} cells of {self.mf.path} (tags: {found})")
            return idx
        if 'cell_set' in sel:
            name = sel['cell_set']
            if cells is None or name not in cells.sets:
                have = sorted(cells.sets) if cells is not None else []
                raise self.err(f"{ctx}: cell set {name!r} has no {ctype} cells in {self.mf.path} (sets: {have})")
            return np.unique(cells.sets[name])
        if 'cell_data' in sel:
            key = sel['cell_data']
            if cells is None or key not in cells.fields:
                raise self.err(f"{ctx}: cell data {key!r} not found on the {ctype} cells of {self.mf.path}")
            idx = np.flatnonzero(cells.fields[key] == sel.get('value'))
            if idx.size == 0:
                raise self.err(f"{ctx}: no {ctype} cell has {key} == {sel.get('value')!r}")
            return idx
        if 'elements' in sel:
            idx = np.asarray(sel['elements'], np.int64).ravel()
            if idx.size == 0 or idx.min() < 0 or idx.max() >= n:
                raise self.err(f"{ctx}: element indices must lie in 0-{n - 1} ({ctype} cells), got "
                               f"{'none' if idx.size == 0 else f'{idx.min()}-{idx.max()}'}")
            return np.unique(idx)
        raise self.err(f"{ctx}: unknown cell selector {sel!r} (use physical, cell_set, cell_data or elements)")

    def select_volume(self, sel, ctx: str, only: Optional[str] = None) -> Dict[str, np.ndarray]:
        """Volume cells chosen by ``sel``: {'tetra': idx, 'wedge': idx}; claims them for ``ctx``."""
        out = {}
        if isinstance(sel, dict) and 'elements' in sel:
            idx = np.asarray(sel['elements'], np.int64).ravel()
            if idx.size == 0 or idx.min() < 0 or idx.max() >= self.n_vol:
                raise self.err(f"{ctx}: element indices must lie in 0-{self.n_vol - 1} (volume cells)")
            for t in self.vol_types:
                o, m = self.vol_offset[t], len(self.mf.cells[t].data)
                k = idx[(idx >= o) & (idx < o + m)] - o
                if k.size:
                    out[t] = np.unique(k)
        else:
            errs = []
            for t in self.vol_types:
                try:
                    out[t] = self.select(sel, t, ctx)
                except MeshSpecError as exc:
                    errs.append(exc)
            if not out:
                raise errs[0]
        if only is not None:
            wrong = [t for t in out if t != only and len(out[t])]
            if wrong:
                raise self.err(f"{ctx}: selects {wrong[0]} cells, but this actuator needs {only} cells")
        for t, k in out.items():
            g = k + self.vol_offset[t]
            taken = self.owner[g]
            clash = taken[taken != '']
            if clash.size:
                raise self.err(f"{ctx}: {clash.size} cells are already in {clash[0]}; "
                               "a cell may belong to one region or actuator only")
            self.owner[g] = ctx
        return out

    # -- vertices ------------------------------------------------------------------------------
    def vertex_selection(self, sel, ctx: str) -> np.ndarray:
        pts = self.mf.points
        if not isinstance(sel, dict):
            sel = {'physical': sel}
        if 'indices' in sel:
            idx = np.asarray(sel['indices'], np.int64).ravel()
            if idx.size and (idx.min() < 0 or idx.max() >= len(pts)):
                raise self.err(f"{ctx}: vertex index out of range 0-{len(pts) - 1}")
            return idx
        if 'box' in sel:
            box = np.asarray(sel['box'], float)
            if box.shape != (2, 3):
                raise self.err(f"{ctx}: 'box' must be [[xmin, ymin, zmin], [xmax, ymax, zmax]], got {sel['box']!r}")
            return np.flatnonzero(np.all((pts >= box[0]) & (pts <= box[1]), axis=1))
        if 'plane' in sel:
            pl = sel['plane']
            try:
                p0, nrm = np.asarray(pl['point'], float), np.asarray(pl['normal'], float)
            except (KeyError, TypeError):
                raise self.err(f"{ctx}: 'plane' needs {{'point': [x, y, z], 'normal': [nx, ny, nz]}}")
            if p0.shape != (3,) or nrm.shape != (3,) or not np.linalg.norm(nrm) > 0:
                raise self.err(f"{ctx}: 'plane' needs a 3D point and a non-zero 3D normal")
            tol = float(sel.get('tolerance', 1e-6 * self.diag))
            return np.flatnonzero(np.abs((pts - p0) @ (nrm / np.linalg.norm(nrm))) <= tol)
        # a cell selector of any type: the vertices of those cells
        errs, found = [], []
        for t in self.mf.cells:
            try:
                found.append(self.mf.cells[t].data[self.select(sel, t, ctx)].ravel())
            except MeshSpecError as exc:
                errs.append(exc)
        if not found:
            raise errs[0] if errs else self.err(f"{ctx}: selector {sel!r} matches nothing")
        return np.unique(np.concatenate(found))

    def marker(self, name, sel) -> int:
        ctx = f"marker {name!r}"
        pts = self.mf.points
        if isinstance(sel, int) and not isinstance(sel, bool):
            sel = {'vertex': sel}
        if isinstance(sel, dict) and 'vertex' in sel:
            v = int(sel['vertex'])
            if not 0 <= v < len(pts):
                raise self.err(f"{ctx}: vertex {v} out of range 0-{len(pts) - 1}")
            return v
        if isinstance(sel, dict) and 'point' in sel:
            p = np.asarray(sel['point'], float)
            if p.shape != (3,):
                raise self.err(f"{ctx}: 'point' must be [x, y, z], got {sel['point']!r}")
            d = np.linalg.norm(pts[self.used] - p, axis=1)
            k = int(np.argmin(d))
            tol = float(sel.get('tolerance', 0.05 * self.diag))
            if d[k] > tol:
                raise self.err(f"{ctx}: nearest vertex is {d[k]:.4g} from {p.tolist()} (tolerance {tol:.4g}, "
                               "file units)")
            return int(self.used[k])
        v = np.unique(self.vertex_selection(sel, ctx))
        if v.size != 1:
            raise self.err(f"{ctx}: selector {sel!r} gives {v.size} vertices, expected exactly one")
        return int(v[0])

    # -- cables ----------------------------------------------------------------------------------
    def cable_from_paths(self, a: dict, ctx: str, tets: np.ndarray):
        pts = self.mf.points
        paths = a.get('paths', [a['path']] if 'path' in a else None)
        if not isinstance(paths, list) or not paths:
            raise self.err(f"{ctx}: 'paths' must be a list of polylines [[x, y, z], ...]")
        edges = np.concatenate([pts[tets[:, [i, j]]] for i, j in ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3))])
        h = float(np.median(np.linalg.norm(edges[:, 0] - edges[:, 1], axis=1))) if len(tets) else self.diag / 10
        snap = float(a.get('snap_tolerance', 0.5 * h))
        offset = a.get('apex_offset')
        offset = None if offset is None else np.asarray(offset, float)
        tris, n_gaps, gap_len, path_len = [], None, None, None
        used = self.used
        for s, path in enumerate(paths):
            P = np.asarray(path, float)
            if P.ndim != 2 or P.shape[1] != 3 or len(P) < 2:
                raise self.err(f"{ctx}: path {s} must be a list of >= 2 points [x, y, z]")
            d = np.linalg.norm(pts[used][None] - P[:, None], axis=2)
            k = np.argmin(d, axis=1)
            far = np.flatnonzero(d[np.arange(len(P)), k] > snap)
            if far.size:
                raise self.err(f"{ctx}: path {s} point {far[0]} {P[far[0]].tolist()} is "
                               f"{d[far[0], k[far[0]]]:.4g} from the nearest vertex (snap_tolerance {snap:.4g})")
            v = used[k]
            if 'gaps' in a:
                gaps = [int(g) for g in a['gaps']]
                if any(not 0 <= g < len(P) - 1 for g in gaps):
                    raise self.err(f"{ctx}: 'gaps' indices must lie in 0-{len(P) - 2} (segments of path {s})")
            else:
                gaps = [i for i in range(len(P) - 1) if not _inside(pts, tets, 0.5 * (pts[v[i]] + pts[v[i + 1]]))]
            if n_gaps is None:
                n_gaps = len(gaps)
                gap_len = sum(np.linalg.norm(pts[v[i + 1]] - pts[v[i]]) for i in gaps)
                path_len = float(np.sum(np.linalg.norm(np.diff(pts[v], axis=0), axis=1)))
            elif len(gaps) != n_gaps:
                raise self.err(f"{ctx}: path {s} crosses {len(gaps)} gaps, path 0 crosses {n_gaps}; "
                               "parallel strands must cross the same gaps")
            for i in gaps:
                ia, ib = v[i], v[i + 1]
                if ia == ib:
                    raise self.err(f"{ctx}: path {s} segment {i} snaps both ends to vertex {ia}")
                if offset is not None:
                    apexes = [self._nearest_other(pts[ia] + offset, (ia, ib)),
                              self._nearest_other(pts[ib] + offset, (ia, ib))]
                else:
                    apexes = [self._nearest_other(0.5 * (pts[ia] + pts[ib]), (ia, ib))]
                for ap in apexes:
                    area = np.linalg.norm(np.cross(pts[ib] - pts[ia], pts[ap] - pts[ia]))
                    if not area > 1e-12 * h * h:
                        raise self.err(f"{ctx}: apex vertex {ap} is on the cable line of segment {i}; "
                                       "set 'apex_offset'")
                    tris.append([ia, ib, ap])
        if not n_gaps:
            raise self.err(f"{ctx}: the cable paths cross no gap (every segment midpoint lies inside the body); "
                           "list the free segments with 'gaps'")
        tris = np.array(tris, np.int64)
        mult = len(tris) // n_gaps
        total = float(a.get('total_length', path_len))
        return tris, mult, total, gap_len, h

    def _nearest_other(self, p, exclude):
        cand = self.used[~np.isin(self.used, exclude)]
        return int(cand[np.argmin(np.linalg.norm(self.mf.points[cand] - p, axis=1))])


def _inside(pts: np.ndarray, tets: np.ndarray, p: np.ndarray, tol: float = 1e-9) -> bool:
    """Point in (or on the boundary of) any tetrahedron."""
    a, b, c, d = (pts[tets[:, i]] for i in range(4))
    T = np.stack([b - a, c - a, d - a], axis=2)
    ok = np.abs(np.linalg.det(T)) > 0
    lam = np.linalg.solve(T[ok], (p - a[ok])[:, :, None])[:, :, 0]
    return bool(np.any(np.all(lam >= -tol, axis=1) & (lam.sum(axis=1) <= 1 + tol)))


def _bounds(a: dict, default, ctx: str, err):
    b = a.get('bounds', default)
    if not isinstance(b, (list, tuple)) or len(b) != 2:
        raise err(f"{ctx}: 'bounds' must be [lower, upper], got {b!r}")
    lo = -np.inf if b[0] is None else float(b[0])
    hi = np.inf if b[1] is None else float(b[1])
    if not lo < hi:
        raise err(f"{ctx}: bounds {b!r} must have lower < upper")
    return (lo, hi)


def load_spec(spec: Union[str, dict]) -> tuple:
    """Spec dict and a name for messages from a path or a dict."""
    if isinstance(spec, dict):
        return spec, 'spec'
    if not os.path.exists(spec):
        raise MeshSpecError(f"spec file {spec!r} not found")
    try:
        with open(spec) as fh:
            data = json.load(fh)
    except json.JSONDecodeError as exc:
        raise MeshSpecError(f"spec file {spec!r} is not valid JSON: {exc}")
    if not isinstance(data, dict):
        raise MeshSpecError(f"spec file {spec!r} must hold a JSON object")
    return data, spec


KNOWN_KEYS = {'units', 'scale', 'default_shape_parameter', 'regions', 'fixed', 'actuators', 'markers',
              'description', 'format', 'source'}


def load_mesh_with_spec(mesh_path: str, spec: Union[str, dict]) -> SoftMesh:
    """A :class:`SoftMesh` from a mesh file and its JSON spec (see the module docstring).

    Parameters
    ----------
    mesh_path : str
        meshio volume mesh (``.msh``, ``.vtu``, ``.mesh``, ...) or TetGen ``.node``/``.ele``.
    spec : str or dict
        Path of the JSON spec, or the spec itself.

    Returns
    -------
    SoftMesh
        Vertices in metres (unused file vertices dropped; ``info['file_vertex']`` maps back),
        body groups per region, actuation groups and actuators in spec order, fixed vertices
        and markers. ``info['model']`` is ``'file:<name>'``.

    Raises
    ------
    MeshSpecError
        Missing or unreadable file, unknown format, a spec naming a missing tag or set, an empty
        selection, no fixed vertices, ...
    """
    spec, name = load_spec(spec)
    unknown = set(spec) - KNOWN_KEYS
    if unknown:
        raise MeshSpecError(f"{name}: unknown keys {sorted(unknown)} (known: {sorted(KNOWN_KEYS)})")
    mf = read_mesh_file(mesh_path)
    ld = _Loader(mf, spec, name)
    err = ld.err
    cells = mf.cells
    # every vertex of a volume cell (cable triangles must use those too)
    ld.used = np.unique(np.concatenate([cells[t].data.ravel() for t in ld.vol_types]))
    tets_all = cells['tetra'].data if 'tetra' in cells else np.zeros((0, 4), np.int64)

    groups: List[ElementGroup] = []
    actuators: List[Actuator] = []
    # actuators first claim their cells, so regions naming overlapping tags fail loudly
    acts = spec.get('actuators', [])
    if not isinstance(acts, list):
        raise err("'actuators' must be a list")
    names = set()
    for i, a in enumerate(acts):
        if not isinstance(a, dict) or 'name' not in a or 'type' not in a:
            raise err(f"actuator #{i} needs 'name' and 'type' (cable, pneumatic or dea)")
        an, kind = str(a['name']), a['type']
        ctx = f"actuator {an!r}"
        if an in names:
            raise err(f"{ctx}: duplicate name")
        names.add(an)
        weight = float(a.get('weight', ACTUATION_WEIGHT))
        if kind in ('pneumatic', 'dea'):
            if 'cells' not in a:
                raise err(f"{ctx}: a {kind} actuator needs 'cells'")
            ctype = 'tetra' if kind == 'pneumatic' else 'wedge'
            sel = ld.select_volume(a['cells'], ctx, only=ctype)
            groups.append(ElementGroup(an, kind, cells[ctype].data[sel[ctype]], weight=weight))
            default = (0.2, 4.0) if kind == 'pneumatic' else (0.3, 2.0)
            actuators.append(Actuator(an, an, bounds=_bounds(a, default, ctx, err)))
        elif kind == 'cable':
            if 'cells' in a:
                idx = ld.select(a['cells'], 'triangle', ctx)  # raises when the file has no such triangles
                tris = cells['triangle'].data[idx]
                mult = int(a.get('segment_multiplicity', 1))
                gap = float(np.linalg.norm(mf.points[tris[:, 1]] - mf.points[tris[:, 0]], axis=1).sum()) / mult
                if 'total_length' not in a:
                    raise err(f"{ctx}: a cable given by 'cells' needs 'total_length' (L of eq. 6)")
                total = float(a['total_length'])
                h = None
            elif 'paths' in a or 'path' in a:
                tris, mult, total, gap, h = ld.cable_from_paths(a, ctx, tets_all)
            else:
                raise err(f"{ctx}: a cable needs 'paths' (polylines) or 'cells' (triangles a, b, apex)")
            bad = ~np.isin(tris, ld.used)
            if bad.any():
                raise err(f"{ctx}: cable triangles use vertex {tris[bad][0]} which is not part of the body")
            if total < gap * (1 - 1e-9):
                raise err(f"{ctx}: total_length {total} is shorter than the gap segments ({gap:.6g})")
            if 'thickness' in a:
                thick = float(a['thickness'])
            else:
                if h is None:
                    e = mf.points[tets_all[:, 0]] - mf.points[tets_all[:, 1]] if len(tets_all) else None
                    h = float(np.median(np.linalg.norm(e, axis=1))) if e is not None else ld.diag / 10
                thick = CABLE_SHEET_FRACTION * h
            groups.append(ElementGroup(an, 'cable', tris, weight=weight, thickness=thick * ld.scale))
            default = (1.0 - 0.85 * gap / total, 1.0)
            actuators.append(Actuator(an, an, total_length=total * ld.scale, bounds=_bounds(a, default, ctx, err),
                                      segment_multiplicity=mult))
        else:
            raise err(f"{ctx}: unknown type {kind!r}; expected cable, pneumatic or dea")

    regions = spec.get('regions', [])
    if not isinstance(regions, list):
        raise err("'regions' must be a list")
    body_groups = []
    for i, r in enumerate(regions):
        if not isinstance(r, dict) or 'cells' not in r:
            raise err(f"region #{i} needs 'cells' (a cell selector) and 'shape_parameter'")
        rn = str(r.get('name', f'region_{i}'))
        ctx = f"region {rn!r}"
        if rn in names:
            raise err(f"{ctx}: duplicate name")
        names.add(rn)
        rw = r.get('shape_parameter', r.get('R_w', spec.get('default_shape_parameter', 1.0)))
        sel = ld.select_volume(r['cells'], ctx)
        w = float(r.get('weight', BODY_WEIGHT))
        for t in ld.vol_types:
            if t in sel and len(sel[t]):
                gname = rn if len(sel) == 1 or t == 'tetra' else f'{rn}_prisms'
                body_groups.append(_body_group(gname, cells[t].data[sel[t]], rw, w, err, ctx))
    free = np.flatnonzero(ld.owner == '')
    if free.size:
        rw = spec.get('default_shape_parameter', 1.0)
        for t in ld.vol_types:
            o, m = ld.vol_offset[t], len(cells[t].data)
            k = free[(free >= o) & (free < o + m)] - o
            if k.size:
                gname = 'body' if t == 'tetra' else 'body_prisms'
                while gname in names:
                    gname += '_'
                body_groups.append(_body_group(gname, cells[t].data[k], rw, BODY_WEIGHT, err, 'default region'))
    groups = body_groups + groups

    if 'fixed' not in spec or not spec['fixed']:
        raise err("no fixed vertices: add 'fixed' (a box, plane, indices or cell selector for the base)")
    fsel = spec['fixed'] if isinstance(spec['fixed'], list) else [spec['fixed']]
    fixed = []
    for i, s in enumerate(fsel):
        v = ld.vertex_selection(s, f"fixed #{i}")
        v = v[np.isin(v, ld.used)]
        if v.size == 0:
            raise err(f"fixed #{i} {s!r} selects no vertex of the body (no fixed vertices)")
        fixed.append(v)
    fixed = np.unique(np.concatenate(fixed))

    markers = {}
    msp = spec.get('markers', {})
    if not isinstance(msp, dict):
        raise err("'markers' must be an object {name: selector}")
    for mname, sel in msp.items():
        v = ld.marker(mname, sel)
        if not np.isin(v, ld.used):
            raise err(f"marker {mname!r}: vertex {v} is not part of any volume cell")
        markers[mname] = v

    # compact: drop file vertices no element uses (they would make the global system singular)
    remap = np.full(len(mf.points), -1, np.int64)
    remap[ld.used] = np.arange(len(ld.used))
    for g in groups:
        g.elements = remap[g.elements]
    mesh = SoftMesh(mf.points[ld.used] * ld.scale, groups, fixed=remap[fixed], actuators=actuators,
                    markers={k: int(remap[v]) for k, v in markers.items()},
                    info={'model': f'file:{os.path.basename(mesh_path)}', 'mesh_file': mesh_path,
                          'spec': name, 'scale': ld.scale, 'file_vertex': ld.used})
    orient_tets(mesh)
    return mesh


def _body_group(name, elements, rw, weight, err, ctx):
    try:
        return ElementGroup(name, 'body', elements, weight=weight, shape_parameter=float(rw))
    except (TypeError, ValueError) as exc:
        raise err(f"{ctx}: {exc}")


# --- writing ------------------------------------------------------------------------------------
def export_mesh_with_spec(mesh: SoftMesh, mesh_path: str, spec_path: Optional[str] = None,
                          units: str = 'm') -> dict:
    """Write a :class:`SoftMesh` as a mesh file plus a JSON spec that loads back to the same robot.

    Each element group becomes a physical group (tag = group index + 1, named after the group
    in gmsh files); fixed vertices and markers are written as vertex indices.

    Parameters
    ----------
    mesh : SoftMesh
    mesh_path : str
        ``.msh`` (gmsh 2.2 ASCII), any other meshio extension, or ``.node``/``.ele`` (TetGen;
        tetrahedra only, the group tag becomes the region attribute).
    spec_path : str, optional
        Where to write the spec (default: the mesh path with ``.json``).
    units : str
        Units of the written coordinates (and of every length in the spec).

    Returns
    -------
    dict
        The spec.
    """
    if units not in UNITS:
        raise MeshSpecError(f"unknown units {units!r}; use one of {sorted(UNITS)}")
    s = UNITS[units]
    x = mesh.vertices / s
    tags = {g.name: i + 1 for i, g in enumerate(mesh.groups)}
    regions, acts = [], []
    for g in mesh.groups:
        if g.kind != 'body':
            continue
        rw = np.unique(g.shape_parameter)
        if rw.size != 1:
            raise MeshSpecError(f"group {g.name!r} has per-element R_w; the spec holds one R_w per region")
        r = dict(name=g.name, cells={'physical': tags[g.name]}, shape_parameter=float(rw[0]))
        if g.weight != BODY_WEIGHT:
            r['weight'] = g.weight
        regions.append(r)
    for a in mesh.actuators:
        g = mesh.group(a.group)
        d = dict(name=a.name, type=g.kind, cells={'physical': tags[g.name]},
                 bounds=[None if not np.isfinite(b) else float(b) for b in a.bounds])
        if g.kind == 'cable':
            d.update(total_length=a.total_length / s, segment_multiplicity=int(a.segment_multiplicity),
                     thickness=g.thickness / s)
        if g.weight != ACTUATION_WEIGHT:
            d['weight'] = g.weight
        acts.append(d)
    spec = dict(description=f"exported from softkin model {mesh.info.get('model', '?')}", units=units,
                regions=regions, fixed=[{'indices': mesh.fixed.tolist()}], actuators=acts,
                markers={k: {'vertex': int(v)} for k, v in mesh.markers.items()})
    base = _tetgen_base(mesh_path)
    if base is not None:
        if any(g.k != 4 for g in mesh.groups):
            raise MeshSpecError("TetGen .node/.ele holds tetrahedra only; this mesh has triangles or prisms "
                                "(use .msh or .vtu)")
        tets = np.concatenate([g.elements for g in mesh.groups])
        attr = np.concatenate([np.full(len(g.elements), tags[g.name]) for g in mesh.groups])
        write_tetgen(base, x, tets, attributes=attr)
    else:
        import meshio
        ctype = {3: 'triangle', 4: 'tetra', 6: 'wedge'}
        cells = [(ctype[g.k], g.elements) for g in mesh.groups]
        phys = [np.full(len(g.elements), tags[g.name], np.int32) for g in mesh.groups]
        dims = {3: 2, 4: 3, 6: 3}
        field = {g.name: np.array([tags[g.name], dims[g.k]]) for g in mesh.groups}
        m = meshio.Mesh(x, cells, cell_data={'gmsh:physical': phys, 'gmsh:geometrical': phys}, field_data=field)
        if mesh_path.endswith('.msh'):
            meshio.write(mesh_path, m, file_format='gmsh22', binary=False)
        else:
            meshio.write(mesh_path, m)
    spec_path = spec_path or os.path.splitext(mesh_path)[0] + '.json'
    with open(spec_path, 'w') as fh:
        json.dump(spec, fh, indent=1)
        fh.write('\n')
    return spec
