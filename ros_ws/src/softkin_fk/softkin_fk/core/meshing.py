"""Mesh generation: structured voxel tetrahedralisation, TetGen boxes, extruded prism strips.

The parametric robot models (:mod:`softkin_fk.core.models`) are built on a regular grid of
cubes of edge ``h``: each kept cube is split into six tetrahedra around its main diagonal
(Kuhn / Freudenthal split), which is conforming between neighbouring cubes. This keeps
feature positions (cable holes, chamber walls) on grid vertices at every resolution.
Unstructured tetrahedra of a box come from the ``tetgen`` PyPI package.
"""
from __future__ import annotations

import itertools

import numpy as np

# The six tetrahedra of the Kuhn split of a unit cube: paths 000 -> e_a -> e_a+e_b -> 111.
_CORNER = {c: i for i, c in enumerate(itertools.product((0, 1), repeat=3))}
_KUHN = []
for perm in itertools.permutations(range(3)):
    p = [0, 0, 0]
    path = [tuple(p)]
    for axis in perm:
        p[axis] = 1
        path.append(tuple(p))
    _KUHN.append([_CORNER[c] for c in path])
_KUHN = np.array(_KUHN, dtype=np.int64)
_CORNER_OFFSETS = np.array(list(itertools.product((0, 1), repeat=3)), dtype=np.int64)


def voxel_tets(cell_mask: np.ndarray, h: float, origin=(0.0, 0.0, 0.0), mirror_z_from: int = -1):
    """Tetrahedralise the kept cells of a regular grid (6 tets per cube).

    Parameters
    ----------
    cell_mask : ndarray of bool, shape (n_x, n_y, n_z)
        True for kept cubes; cube (i, j, k) spans ``origin + h * [i, i+1] x [j, j+1] x [k, k+1]``.
    h : float
        Cube edge (m).
    origin : array_like, shape (3,)
        Position of grid corner (0, 0, 0) (m).
    mirror_z_from : int
        If >= 0, cubes with z index >= this use the z-mirrored split, so a mesh with
        ``mirror_z_from = n_z / 2`` is mirror-symmetric about its mid plane (a planar robot
        then has no spurious out-of-plane bias). The split stays conforming.

    Returns
    -------
    vertices : ndarray, shape (n_v, 3)
        Used grid vertices (m).
    tets : ndarray of int, shape (6 * n_cells, 4)
        Positively oriented tetrahedra.
    cell_of_tet : ndarray of int, shape (6 * n_cells, 3)
        Grid index (i, j, k) of the cube each tetrahedron came from.
    grid_index : ndarray of int, shape (n_x + 1, n_y + 1, n_z + 1)
        Vertex index of each grid point, -1 where unused.
    """
    mask = np.asarray(cell_mask, bool)
    if mask.ndim != 3 or not mask.any():
        raise ValueError(f"cell mask must be a non-empty 3D boolean array, got shape {mask.shape} "
                         f"with {int(mask.sum())} cells")
    if h <= 0:
        raise ValueError(f"cell size h = {h} m must be positive")
    nx, ny, nz = mask.shape
    cells = np.argwhere(mask)
    gx, gy, gz = nx + 1, ny + 1, nz + 1
    offsets = np.broadcast_to(_CORNER_OFFSETS, (len(cells), 8, 3)).copy()
    if mirror_z_from >= 0:
        flip = cells[:, 2] >= mirror_z_from
        offsets[flip, :, 2] = 1 - offsets[flip, :, 2]
    corners = cells[:, None, :] + offsets                                 # (n_c, 8, 3)
    corner_ids = (corners[..., 0] * gy + corners[..., 1]) * gz + corners[..., 2]
    tets_grid = corner_ids[:, _KUHN].reshape(-1, 4)
    used = np.unique(tets_grid)
    grid_index = np.full(gx * gy * gz, -1, np.int64)
    grid_index[used] = np.arange(len(used))
    tets = grid_index[tets_grid]
    ijk = np.stack(np.unravel_index(used, (gx, gy, gz)), axis=1)
    vertices = np.asarray(origin, float) + h * ijk.astype(float)
    # orient
    a, b, c, d = (vertices[tets[:, i]] for i in range(4))
    neg = np.einsum('ij,ij->i', np.cross(b - a, c - a), d - a) < 0
    tets[neg] = tets[neg][:, [1, 0, 2, 3]]
    cell_of_tet = np.repeat(cells, 6, axis=0)
    return vertices, tets, cell_of_tet, grid_index.reshape(gx, gy, gz)


def tetgen_box(size, max_volume: float, origin=(0.0, 0.0, 0.0), quality: float = 1.5):
    """Unstructured quality tetrahedra of a box through TetGen (``tetgen`` PyPI package).

    Parameters
    ----------
    size : array_like, shape (3,)
        Box edge lengths (m).
    max_volume : float
        Maximum tetrahedron volume (m^3).
    origin : array_like, shape (3,)
        Minimum corner (m).
    quality : float
        TetGen radius-edge ratio bound.

    Returns
    -------
    vertices : ndarray, shape (n_v, 3)
    tets : ndarray of int, shape (n_t, 4)
    """
    import tetgen
    size = np.asarray(size, float)
    corners = np.array(list(itertools.product((0, 1), repeat=3)), float) * size + np.asarray(origin, float)
    # 12 outward triangles of the box (corner index = 4x + 2y + z)
    faces = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                      [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    # scale to O(1) for TetGen's tolerances, then back
    s = float(size.max())
    tg = tetgen.TetGen(corners / s, faces)
    v, t = tg.tetrahedralize(quality=True, minratio=quality, maxvolume=max_volume / s ** 3, verbose=0)[:2]
    v = np.asarray(v, float) * s
    t = np.asarray(t, np.int64)[:, :4]
    a, b, c, d = (v[t[:, i]] for i in range(4))
    neg = np.einsum('ij,ij->i', np.cross(b - a, c - a), d - a) < 0
    t[neg] = t[neg][:, [1, 0, 2, 3]]
    return v, t


def extrude_prisms(points2d: np.ndarray, triangles: np.ndarray, thickness: float):
    """Extrude a planar triangulation (z = 0 .. thickness) into a layer of prisms.

    Parameters
    ----------
    points2d : ndarray, shape (n, 2)
        Planar vertices (m).
    triangles : ndarray of int, shape (n_t, 3)
        Counter-clockwise triangles.
    thickness : float
        Layer thickness (m).

    Returns
    -------
    vertices : ndarray, shape (2 n, 3)
        Bottom layer (z = 0) then top layer (z = thickness).
    prisms : ndarray of int, shape (n_t, 6)
        ``(t0, t1, t2, b0, b1, b2)``: top triangle, then the bottom triangle below it.
    """
    p = np.asarray(points2d, float)
    n = len(p)
    verts = np.vstack([np.column_stack([p, np.zeros(n)]), np.column_stack([p, np.full(n, thickness)])])
    tri = np.asarray(triangles, np.int64)
    prisms = np.column_stack([tri + n, tri])
    return verts, prisms


def grid_triangles(nx: int, ny: int, h: float):
    """Right-triangle grid of an (nx h) x (ny h) rectangle.

    Returns
    -------
    points : ndarray, shape ((nx+1)(ny+1), 2)
    triangles : ndarray of int, shape (2 nx ny, 3)
        Counter-clockwise.
    """
    ii, jj = np.meshgrid(np.arange(nx + 1), np.arange(ny + 1), indexing='ij')
    pts = np.column_stack([ii.ravel(), jj.ravel()]).astype(float) * h
    idx = lambda i, j: i * (ny + 1) + j  # noqa: E731
    tris = []
    for i in range(nx):
        for j in range(ny):
            a, b, c, d = idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1)
            tris += [[a, b, c], [a, c, d]]
    return pts, np.array(tris, np.int64)
