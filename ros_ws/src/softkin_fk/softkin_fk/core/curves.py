"""Built-in target curves for trajectory following (Fig. 13), waypoint files, and the finger's workspace.

Both curves lie in the finger's bending plane z = 12.5 mm (metres at the API) inside the tip
workspace of the **resolution-2** finger (``models.DEFAULT_FINGER_RESOLUTION``), at least 2 mm
from its boundary:

* ``'L'`` (N = 55): a 9 mm leg down from (98, 62.5) mm to the corner (98, 53.5) mm, then a
  7 mm leg to (105, 53.5) mm, sampled uniformly by arc length (the paper's "L", Fig. 13).
  Smallest distance of a waypoint from the workspace boundary: 2.2 mm.
* ``'flame'`` (N = 85): a closed flame outline 6 mm wide and 9.4 mm tall, pointed top, round
  bottom, centred (bounding box) at (99, 57.5) mm, sampled uniformly in its parameter.
  Smallest distance of a waypoint from the workspace boundary: 2.0 mm.

How they were placed: the workspace is the image of the actuation box under forward
kinematics. ``sample_configuration_space`` gave the tip on a 7 x 7 x 7 grid of cable ratios
(s_j from each lower bound to 1, resolution 2; 343 samples); the image of each grid cell is
approximated by the convex hull of its 8 corner tips, and the union of those hulls, rasterised
at 0.05 mm, is the workspace (:func:`workspace_region`). It is a curved band from the rest tip
(120, 25) mm to about (71, 76) mm, up to 11.2 mm wide (largest inscribed circle: radius 5.6 mm
at (98.8, 57.4) mm): the finger's three cables all pull on its upper side. The curves keep
their proportions from the paper's figure and were positioned (and the 'L' sized) by a grid
search for the largest distance of all curve points from the boundary, rounded to 0.5 mm;
the margins above are from samples converged to 1e-9 m.

Check (``softkin workspace --ik-every 5``: FK samples at 1e-9 m, then independent
Gauss-Newton IK on every 5th waypoint from the nearest sample's actuation): 'L' 11/11
waypoints within lambda = 0.2 mm (largest error 0.072 mm), 'flame' 17/17 (largest 0.183 mm),
each from the first start. The command draws ``runs/softkin/workspace/curves_workspace.png``
(samples, boundary-distance shading, both curves, IK results).
"""
from __future__ import annotations

import dataclasses
import itertools

import numpy as np

MM = 1e-3
#: the finger's mid plane across its width (bending plane of the planar finger)
FINGER_PLANE_Z = 12.5 * MM

#: 'L' corners (mm): start, corner, end
L_CORNERS_MM = ((98.0, 62.5), (98.0, 53.5), (105.0, 53.5))
#: flame: bounding-box centre (mm), width and height (mm)
FLAME_CENTRE_MM = (99.0, 57.5)
FLAME_WIDTH_MM = 6.0
FLAME_HEIGHT_MM = 9.4


def curve_L(n: int = 55) -> np.ndarray:
    """The 'L' trajectory: (n, 3) points (m), uniform in arc length (see module docstring)."""
    corners = np.array(L_CORNERS_MM) * MM
    seg = np.linalg.norm(np.diff(corners, axis=0), axis=1)
    s = np.linspace(0.0, seg.sum(), n)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    pts = np.empty((n, 2))
    for i, si in enumerate(s):
        k = min(np.searchsorted(cum, si, side='right') - 1, len(seg) - 1)
        u = (si - cum[k]) / seg[k]
        pts[i] = corners[k] + u * (corners[k + 1] - corners[k])
    return np.column_stack([pts, np.full(n, FINGER_PLANE_Z)])


def curve_flame(n: int = 85) -> np.ndarray:
    """The 'flame' trajectory: (n, 3) points (m) of a closed flame outline (see module docstring)."""
    t = np.linspace(0.0, 2 * np.pi, n)
    # a teardrop: round bottom, pointed top (flame tip at t = pi / 2); w in [-2.5, 2.5], h in [-4.7, 4.7]
    w = 2.5 * np.cos(t) * (1 - 0.5 * (np.sin(t) > 0) * np.sin(t) ** 2)
    h = 4.0 * np.sin(t) - 0.7 * np.sin(3 * t)
    cx, cy = FLAME_CENTRE_MM
    pts = np.column_stack([cx + w * FLAME_WIDTH_MM / 5.0, cy + h * FLAME_HEIGHT_MM / 9.4]) * MM
    return np.column_stack([pts, np.full(n, FINGER_PLANE_Z)])


CURVES = {'L': curve_L, 'flame': curve_flame}


def read_waypoints_csv(path: str, scale: float = 1.0) -> np.ndarray:
    """Waypoints from a CSV file with columns x, y[, z] (header optional).

    Parameters
    ----------
    path : str
    scale : float
        Factor to metres (0.001 for millimetres). Missing z is the finger plane.

    Returns
    -------
    ndarray, shape (n, 3)

    Raises
    ------
    ValueError
        If the file has fewer than 2 columns or no rows.
    """
    rows = []
    with open(path) as fh:
        for k, line in enumerate(fh):
            line = line.strip()
            if not line or line.startswith('#'):
                continue
            parts = [p for p in line.replace(';', ',').split(',') if p.strip() != '']
            try:
                vals = [float(p) for p in parts]
            except ValueError:
                if k == 0:
                    continue  # header
                raise ValueError(f"{path}: line {k + 1} is not numeric: {line!r}")
            if len(vals) < 2:
                raise ValueError(f"{path}: line {k + 1} has {len(vals)} columns, expected x, y[, z]")
            rows.append(vals[:3])
    if not rows:
        raise ValueError(f"{path}: no waypoints found")
    out = np.array([r + [FINGER_PLANE_Z / scale] if len(r) == 2 else r for r in rows], float) * scale
    return out


# --- workspace ------------------------------------------------------------------------------------
@dataclasses.dataclass
class WorkspaceRegion:
    """A rasterised planar workspace (x-y plane) with each pixel's distance to its boundary.

    Attributes
    ----------
    xs, ys : ndarray
        Pixel centres (m).
    inside : ndarray of bool, shape (len(xs), len(ys))
    distance : ndarray, shape (len(xs), len(ys))
        Distance (m) of inside pixels from the nearest outside pixel; 0 outside.
    """

    xs: np.ndarray
    ys: np.ndarray
    inside: np.ndarray
    distance: np.ndarray

    def margin(self, points) -> np.ndarray:
        """Distance (m) of points (n, >= 2) from the workspace boundary; 0 outside."""
        from scipy.interpolate import RegularGridInterpolator
        f = RegularGridInterpolator((self.xs, self.ys), self.distance, bounds_error=False, fill_value=0.0)
        return f(np.asarray(points, float)[:, :2])

    def largest_inscribed_circle(self) -> tuple:
        """(radius, centre (2,)) in metres."""
        i, j = np.unravel_index(np.argmax(self.distance), self.distance.shape)
        return float(self.distance[i, j]), np.array([self.xs[i], self.ys[j]])


def workspace_region(actuations: np.ndarray, points: np.ndarray, pixel: float = 0.05 * MM) -> WorkspaceRegion:
    """Planar workspace from tip samples on a full actuation grid (``sample_configuration_space``).

    The image of every grid cell (a box in actuation space) is approximated by the convex hull
    of its corner tips (x, y); the union of the hulls, rasterised at ``pixel``, is the region.

    Parameters
    ----------
    actuations : ndarray, shape (n ** n_a, n_a)
        The grid (any order), n values per actuator.
    points : ndarray, shape (n ** n_a, >= 2)
        Tip positions (m); x and y are used (the finger's bending plane).
    pixel : float
        Raster size (m).

    Returns
    -------
    WorkspaceRegion
    """
    from scipy import ndimage
    from scipy.spatial import ConvexHull, QhullError
    A = np.asarray(actuations, float)
    P = np.asarray(points, float)[:, :2]
    n_a = A.shape[1]
    n = int(round(len(A) ** (1.0 / n_a)))
    if n ** n_a != len(A) or n < 2:
        raise ValueError(f"{len(A)} samples are not a full grid of n^{n_a} actuations")
    lo, hi = A.min(axis=0), A.max(axis=0)
    idx = np.rint((A - lo) / np.where(hi > lo, hi - lo, 1.0) * (n - 1)).astype(np.int64)
    lut = {tuple(i): k for k, i in enumerate(idx)}
    x0, y0 = P.min(axis=0) - 4 * pixel
    x1, y1 = P.max(axis=0) + 4 * pixel
    xs, ys = np.arange(x0, x1, pixel), np.arange(y0, y1, pixel)
    inside = np.zeros((len(xs), len(ys)), bool)
    for cell in itertools.product(range(n - 1), repeat=n_a):
        c = P[[lut[tuple(np.add(cell, o))] for o in itertools.product((0, 1), repeat=n_a)]]
        try:
            eq = ConvexHull(c).equations
        except QhullError:  # a degenerate (flat) cell image adds no area
            continue
        i0, i1 = np.searchsorted(xs, [c[:, 0].min(), c[:, 0].max()])
        j0, j1 = np.searchsorted(ys, [c[:, 1].min(), c[:, 1].max()])
        if i1 <= i0 or j1 <= j0:
            continue
        X, Y = np.meshgrid(xs[i0:i1], ys[j0:j1], indexing='ij')
        q = np.stack([X, Y, np.ones_like(X)], axis=-1)
        inside[i0:i1, j0:j1] |= np.all(q @ eq.T <= 1e-12, axis=-1)
    distance = ndimage.distance_transform_edt(inside) * pixel
    return WorkspaceRegion(xs, ys, inside, distance)
