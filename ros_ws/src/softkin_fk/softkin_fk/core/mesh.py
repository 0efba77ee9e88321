"""Volumetric meshes of soft robots: vertices, element groups, actuators, fixed vertices.

A :class:`SoftMesh` holds the rest shape of a robot (paper Sec. II-A) as

* ``vertices`` -- (n_v, 3) rest positions in metres,
* element groups -- :class:`ElementGroup`, each a (n_e, k) connectivity of one element type
  (k = 3 cable triangles, k = 4 tetrahedra, k = 6 prisms) and one role
  (``'body'`` with shape parameter R_w, or an actuation kind),
* actuators -- :class:`Actuator`, each driving one actuation group with one scalar ratio
  (cable shortening s, DEA area stretch lambda, pneumatic volume ratio alpha; eq. 6-8),
* fixed vertices (the base) and named marker vertices (e.g. the tip).

Prism vertex order is ``(t0, t1, t2, b0, b1, b2)``: a top triangle and the bottom triangle
below it. Cable triangles are ``(a, b, apex)`` with the cable running from ``a`` to ``b``.

I/O goes through meshio (any volume format it reads: .msh, .vtu, .vtk, .mesh, ...) and a
small reader/writer for TetGen ``.node``/``.ele`` files (with region attributes). A user's mesh
with its element groups, actuators, fixed vertices and markers loads from a mesh file plus a
JSON spec with :func:`softkin_fk.core.mesh_spec.load_mesh_with_spec`.
"""
from __future__ import annotations

import dataclasses
import os
from typing import Dict, List, Optional, Sequence

import numpy as np

#: element roles understood by the local step
ELEMENT_KINDS = ('body', 'cable', 'dea', 'pneumatic')
#: paper Sec. III-A: actuation elements weigh 5.0, body elements 1.0
ACTUATION_WEIGHT = 5.0
BODY_WEIGHT = 1.0


@dataclasses.dataclass
class ElementGroup:
    """A set of elements of one type and role.

    Parameters
    ----------
    name : str
        Unique name of the group (e.g. ``'body'``, ``'cable_0'``).
    kind : str
        One of ``'body'``, ``'cable'``, ``'dea'``, ``'pneumatic'``.
    elements : ndarray of int, shape (n_e, k)
        Vertex indices; k = 3 (cable triangle), 4 (tetrahedron) or 6 (prism).
    weight : float, optional
        Element weight w_i of eq. 9; default 1.0 for body and 5.0 for actuation elements
        (paper Sec. III-A).
    shape_parameter : ndarray, shape (n_e,)
        R_w of eq. 5 per element (1 = rigid, 0 = volume-preserving super-soft);
        only used by body elements.
    thickness : float
        For cable triangles only: the slab thickness (m) a triangle stands for, so that its
        "volume" in eq. 9 is area x thickness.
    """

    name: str
    kind: str
    elements: np.ndarray
    weight: Optional[float] = None
    shape_parameter: Optional[np.ndarray] = None
    thickness: float = 0.0

    def __post_init__(self):
        self.elements = np.ascontiguousarray(self.elements, dtype=np.int64)
        if self.kind not in ELEMENT_KINDS:
            raise ValueError(f"element group {self.name!r}: kind {self.kind!r} is not one of {ELEMENT_KINDS}")
        if self.elements.ndim != 2 or self.elements.shape[1] not in (3, 4, 6):
            raise ValueError(f"element group {self.name!r}: elements have shape {self.elements.shape}, "
                             "expected (n, 3), (n, 4) or (n, 6)")
        n = len(self.elements)
        if self.weight is None:
            self.weight = BODY_WEIGHT if self.kind == 'body' else ACTUATION_WEIGHT
        if not self.weight > 0:
            raise ValueError(f"element group {self.name!r}: weight {self.weight} must be positive")
        if self.shape_parameter is None:
            self.shape_parameter = np.ones(n)
        self.shape_parameter = np.broadcast_to(np.asarray(self.shape_parameter, float), (n,)).copy()
        if np.any((self.shape_parameter < 0) | (self.shape_parameter > 1)):
            raise ValueError(f"element group {self.name!r}: shape parameter R_w must lie in [0, 1], "
                             f"got range [{self.shape_parameter.min()}, {self.shape_parameter.max()}]")
        if self.kind == 'cable' and self.elements.shape[1] != 3:
            raise ValueError(f"cable group {self.name!r} needs triangles (n, 3), got {self.elements.shape}")
        if self.kind == 'dea' and self.elements.shape[1] != 6:
            raise ValueError(f"DEA group {self.name!r} needs prisms (n, 6), got {self.elements.shape}")
        if self.kind == 'pneumatic' and self.elements.shape[1] != 4:
            raise ValueError(f"pneumatic group {self.name!r} needs tetrahedra (n, 4), got {self.elements.shape}")

    @property
    def k(self) -> int:
        """Vertices per element."""
        return int(self.elements.shape[1])


@dataclasses.dataclass
class Actuator:
    """One independently driven actuator (a cable, a DEA membrane or a chamber).

    The scalar actuation ratio ``value`` means s (cable length ratio, eq. 6), lambda (DEA
    area ratio, eq. 7) or alpha (chamber volume ratio, eq. 8); 1.0 is the rest state.

    Parameters
    ----------
    name : str
        Actuator name (e.g. ``'cable_0'``).
    group : str
        Name of the :class:`ElementGroup` of its actuation elements.
    total_length : float
        Cables only: the cable length L (m) of eq. 6 (inside portion L_R plus the gap
        segments l_i). Ignored for DEA and pneumatic actuators.
    bounds : tuple of float
        Allowed range of the actuation ratio (used by IK).
    segment_multiplicity : int
        Cables only: how many triangles stand for each cable segment (a cable crossing a gap
        as a sheet of triangles across the width); eq. 6 is applied to their mean.
    """

    name: str
    group: str
    total_length: float = 0.0
    bounds: tuple = (0.0, np.inf)
    segment_multiplicity: int = 1


@dataclasses.dataclass
class SoftMesh:
    """Rest shape of a soft robot with its element groups, actuators and boundary conditions.

    Parameters
    ----------
    vertices : ndarray, shape (n_v, 3)
        Rest positions (m).
    groups : list of ElementGroup
        Body and actuation element groups.
    fixed : ndarray of int, shape (n_f,)
        Indices of vertices held at their positions (the base).
    actuators : list of Actuator
        Actuators in the order of the actuation vector.
    markers : dict of str to int
        Named vertices (e.g. ``{'tip': 123}``).
    """

    vertices: np.ndarray
    groups: List[ElementGroup]
    fixed: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0, np.int64))
    actuators: List[Actuator] = dataclasses.field(default_factory=list)
    markers: Dict[str, int] = dataclasses.field(default_factory=dict)
    info: Dict[str, object] = dataclasses.field(default_factory=dict)

    def __post_init__(self):
        self.vertices = np.ascontiguousarray(self.vertices, dtype=np.float64)
        if self.vertices.ndim != 2 or self.vertices.shape[1] != 3:
            raise ValueError(f"vertices have shape {self.vertices.shape}, expected (n, 3)")
        self.fixed = np.unique(np.asarray(self.fixed, dtype=np.int64))
        nv = len(self.vertices)
        names = [g.name for g in self.groups]
        if len(set(names)) != len(names):
            raise ValueError(f"element group names must be unique, got {names}")
        for g in self.groups:
            if g.elements.size and (g.elements.min() < 0 or g.elements.max() >= nv):
                raise ValueError(f"element group {g.name!r} indexes vertex {g.elements.max()} "
                                 f"but the mesh has {nv} vertices")
        if self.fixed.size and (self.fixed.min() < 0 or self.fixed.max() >= nv):
            raise ValueError(f"fixed vertex index out of range 0-{nv - 1}")
        for a in self.actuators:
            if a.group not in names:
                raise ValueError(f"actuator {a.name!r} refers to unknown group {a.group!r}; groups: {names}")
            if self.group(a.group).kind == 'body':
                raise ValueError(f"actuator {a.name!r} drives body group {a.group!r}; expected an actuation group")
        for key, idx in self.markers.items():
            if not 0 <= int(idx) < nv:
                raise ValueError(f"marker {key!r} = {idx} is out of range 0-{nv - 1}")

    # --- queries ------------------------------------------------------------------------
    def group(self, name: str) -> ElementGroup:
        """Return the element group called ``name``."""
        for g in self.groups:
            if g.name == name:
                return g
        raise KeyError(f"no element group {name!r}; groups: {[g.name for g in self.groups]}")

    @property
    def n_vertices(self) -> int:
        return len(self.vertices)

    @property
    def tets(self) -> np.ndarray:
        """All tetrahedra (body and pneumatic), shape (n, 4)."""
        parts = [g.elements for g in self.groups if g.k == 4]
        return np.concatenate(parts) if parts else np.zeros((0, 4), np.int64)

    @property
    def n_tets(self) -> int:
        return len(self.tets)

    def actuator_index(self, name: str) -> int:
        for i, a in enumerate(self.actuators):
            if a.name == name:
                return i
        raise KeyError(f"no actuator {name!r}; actuators: {[a.name for a in self.actuators]}")

    def rest_actuation(self) -> np.ndarray:
        """Actuation vector of the rest state (all ratios 1.0), shape (n_actuators,)."""
        return np.ones(len(self.actuators))

    def boundary_faces(self) -> np.ndarray:
        """Triangles on the boundary of the tetrahedral body, shape (n_f, 3), for rendering."""
        tets = self.tets
        if len(tets) == 0:
            return np.zeros((0, 3), np.int64)
        faces = np.concatenate([tets[:, [0, 2, 1]], tets[:, [0, 1, 3]], tets[:, [1, 2, 3]], tets[:, [0, 3, 2]]])
        key = np.sort(faces, axis=1)
        _, inv, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
        return faces[counts[inv.ravel()] == 1]

    def transformed(self, rotation: np.ndarray, translation: np.ndarray) -> 'SoftMesh':
        """Copy of the mesh with vertices mapped by ``x -> rotation @ x + translation``."""
        m = dataclasses.replace(self, vertices=self.vertices @ np.asarray(rotation).T + np.asarray(translation))
        return m


# --- element measures -----------------------------------------------------------------------
def tet_volumes(x: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Signed volumes (m^3) of tetrahedra, shape (n,); positive for right-handed (0,1,2,3)."""
    a, b, c, d = (x[tets[:, i]] for i in range(4))
    return np.einsum('ij,ij->i', np.cross(b - a, c - a), d - a) / 6.0


def prism_volumes(x: np.ndarray, prisms: np.ndarray) -> np.ndarray:
    """Volumes (m^3) of prisms (t0,t1,t2,b0,b1,b2), split into three tetrahedra, shape (n,)."""
    p = prisms
    split = np.stack([p[:, [3, 4, 5, 0]], p[:, [4, 5, 0, 1]], p[:, [5, 0, 1, 2]]], axis=1).reshape(-1, 4)
    return np.abs(tet_volumes(x, split).reshape(-1, 3)).sum(axis=1)


def triangle_areas(x: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """Areas (m^2) of triangles, shape (n,)."""
    a, b, c = (x[tris[:, i]] for i in range(3))
    return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)


def element_measures(x: np.ndarray, group: ElementGroup) -> np.ndarray:
    """The "volume" Vol(V_i) of eq. 9 for each element of a group (m^3), shape (n,).

    Tetrahedra and prisms give their volume; cable triangles give area x the group's slab
    thickness.
    """
    if group.k == 4:
        return np.abs(tet_volumes(x, group.elements))
    if group.k == 6:
        return prism_volumes(x, group.elements)
    return triangle_areas(x, group.elements) * group.thickness


# --- I/O ------------------------------------------------------------------------------------
def read_tetgen(basename: str, return_attributes: bool = False) -> tuple:
    """Read TetGen ``basename.node`` and ``basename.ele``.

    Parameters
    ----------
    basename : str
        Path without extension.
    return_attributes : bool
        Also return the first element attribute (TetGen's region number, ``-A``).

    Returns
    -------
    vertices : ndarray, shape (n_v, 3)
        Positions in the file's units.
    tets : ndarray of int, shape (n_t, 4)
        Zero-based vertex indices.
    attributes : ndarray of int, shape (n_t,), or None
        Only with ``return_attributes``; None when the .ele file has no attribute column.

    Raises
    ------
    ValueError
        Malformed header, wrong dimension or nodes per element, missing node ids or rows.
    """
    def rows(path):
        out = []
        with open(path) as fh:
            for line in fh:
                line = line.split('#', 1)[0].strip()
                if line:
                    out.append(line.split())
        return out

    node_rows = rows(basename + '.node')
    if not node_rows:
        raise ValueError(f"{basename}.node is empty")
    n, dim = int(node_rows[0][0]), int(node_rows[0][1])
    if dim != 3:
        raise ValueError(f"{basename}.node has dimension {dim}, expected 3")
    if len(node_rows) < 1 + n:
        raise ValueError(f"{basename}.node announces {n} nodes but holds {len(node_rows) - 1}")
    nodes = np.array([[float(v) for v in r[:4]] for r in node_rows[1:1 + n]])
    ids = nodes[:, 0].astype(np.int64)
    verts = nodes[:, 1:4]
    ele_rows = rows(basename + '.ele')
    if not ele_rows:
        raise ValueError(f"{basename}.ele is empty")
    ne, npe = int(ele_rows[0][0]), int(ele_rows[0][1])
    n_attr = int(ele_rows[0][2]) if len(ele_rows[0]) > 2 else 0
    if npe not in (4, 10):
        raise ValueError(f"{basename}.ele has {npe} nodes per element, expected 4 (or 10)")
    if len(ele_rows) < 1 + ne:
        raise ValueError(f"{basename}.ele announces {ne} elements but holds {len(ele_rows) - 1}")
    ele = np.array([[int(v) for v in r[1:5]] for r in ele_rows[1:1 + ne]], dtype=np.int64)
    attr = None
    if n_attr > 0:
        attr = np.array([int(round(float(r[1 + npe]))) for r in ele_rows[1:1 + ne]], dtype=np.int64)
    lookup = np.full(ids.max() + 1, -1, np.int64)
    lookup[ids] = np.arange(n)
    if ele.min() < 0 or ele.max() > ids.max():
        raise ValueError(f"{basename}.ele references node ids missing from {basename}.node")
    tets = lookup[ele]
    if np.any(tets < 0):
        raise ValueError(f"{basename}.ele references node ids missing from {basename}.node")
    if return_attributes:
        return verts, tets, attr
    return verts, tets


def write_tetgen(basename: str, vertices: np.ndarray, tets: np.ndarray,
                 attributes: Optional[np.ndarray] = None) -> None:
    """Write TetGen ``basename.node``/``basename.ele`` (zero-based ids).

    ``attributes`` (n_t,) ints, if given, become the element attribute (region number).
    """
    with open(basename + '.node', 'w') as fh:
        fh.write(f"{len(vertices)} 3 0 0\n")
        for i, v in enumerate(vertices):
            fh.write(f"{i} {v[0]:.17g} {v[1]:.17g} {v[2]:.17g}\n")
    with open(basename + '.ele', 'w') as fh:
        fh.write(f"{len(tets)} 4 {0 if attributes is None else 1}\n")
        for i, t in enumerate(tets):
            extra = '' if attributes is None else f" {int(attributes[i])}"
            fh.write(f"{i} {t[0]} {t[1]} {t[2]} {t[3]}{extra}\n")


def read_volume_mesh(path: str, scale: float = 1.0, shape_parameter: float = 1.0,
                     fixed: Optional[Sequence[int]] = None) -> SoftMesh:
    """Load a tetrahedral or prism mesh as a body-only :class:`SoftMesh`.

    Parameters
    ----------
    path : str
        A file meshio reads (``.msh``, ``.vtu``, ``.vtk``, ``.mesh``, ...) or a TetGen
        ``.node``/``.ele`` pair (give either file, or the basename).
    scale : float
        Factor from file units to metres (0.001 for millimetres).
    shape_parameter : float
        R_w given to all body elements.
    fixed : sequence of int, optional
        Fixed vertex indices.

    Returns
    -------
    SoftMesh

    Raises
    ------
    FileNotFoundError
        If the file does not exist.
    ValueError
        If the file holds no tetrahedra or wedges.
    """
    root, ext = os.path.splitext(path)
    candidates = [path, root + '.node', path + '.node']
    if not any(os.path.exists(c) for c in candidates):
        raise FileNotFoundError(f"mesh file {path!r} not found (expected a meshio volume mesh or TetGen .node/.ele)")
    groups = []
    if ext in ('.node', '.ele') or (ext == '' and os.path.exists(path + '.node')):
        verts, tets = read_tetgen(root if ext else path)
        groups.append(ElementGroup('body', 'body', tets, shape_parameter=shape_parameter))
    else:
        import meshio
        m = meshio.read(path)
        verts = np.asarray(m.points, float)
        if verts.shape[1] == 2:
            verts = np.column_stack([verts, np.zeros(len(verts))])
        tets = [c.data for c in m.cells if c.type == 'tetra']
        wedges = [c.data for c in m.cells if c.type == 'wedge']
        if tets:
            groups.append(ElementGroup('body', 'body', np.concatenate(tets), shape_parameter=shape_parameter))
        if wedges:
            groups.append(ElementGroup('body_prisms', 'body', np.concatenate(wedges), shape_parameter=shape_parameter))
        if not groups:
            raise ValueError(f"{path}: no 'tetra' or 'wedge' cells found (cell types: "
                             f"{[c.type for c in m.cells]})")
    mesh = SoftMesh(np.asarray(verts) * scale, groups, fixed=np.zeros(0, np.int64) if fixed is None else fixed)
    orient_tets(mesh)
    return mesh


def write_volume_mesh(path: str, mesh: SoftMesh, positions: Optional[np.ndarray] = None) -> None:
    """Write the mesh (optionally at deformed ``positions``, (n_v, 3) m) through meshio.

    Each element group becomes a cell block; a ``group`` cell-data field holds its index.
    """
    import meshio
    x = mesh.vertices if positions is None else positions
    ctype = {3: 'triangle', 4: 'tetra', 6: 'wedge'}
    cells = [(ctype[g.k], g.elements) for g in mesh.groups]
    data = {'group': [np.full(len(g.elements), i, np.int32) for i, g in enumerate(mesh.groups)]}
    m = meshio.Mesh(x, cells, cell_data=data)
    if path.endswith('.msh'):  # gmsh 4.1 (meshio's default) needs entity tags for mixed cell types
        data = {'gmsh:physical': data['group'], 'gmsh:geometrical': data['group']}
        meshio.write(path, meshio.Mesh(x, cells, cell_data=data), file_format='gmsh22', binary=False)
    else:
        meshio.write(path, m)


def orient_tets(mesh: SoftMesh) -> None:
    """Swap two vertices of negatively oriented tetrahedra in place (all volumes > 0)."""
    for g in mesh.groups:
        if g.k == 4 and len(g.elements):
            neg = tet_volumes(mesh.vertices, g.elements) < 0
            g.elements[neg] = g.elements[neg][:, [1, 0, 2, 3]]
