"""Planar network of discrete elastic rods: nodes, stretching edges and bending triples.

A node may belong to several rods: bending elements are explicit node triples
``(i-1, i, i+1)``, so a joint node (the frog's body corners) simply appears as the
middle node of several triples (paper: a corner node "is associated with three
turning angles and two discrete bending energies").

Units: positions m, stiffness EA in N, EI in N m^2, curvature 1/m, linear density kg/m.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


def signed_turning_angle(e1: np.ndarray, e2: np.ndarray) -> np.ndarray:
    """Signed turning angle phi from edge ``e1`` to edge ``e2`` (counter-clockwise positive).

    Parameters
    ----------
    e1, e2 : ndarray, shape (..., 2)
        Consecutive edge vectors [m].

    Returns
    -------
    ndarray, shape (...)
        phi in (-pi, pi] [rad].
    """
    cross = e1[..., 0] * e2[..., 1] - e1[..., 1] * e2[..., 0]
    dot = np.sum(e1 * e2, axis=-1)
    return np.arctan2(cross, dot)


def discrete_curvature(positions: np.ndarray, bends: np.ndarray, bend_length: np.ndarray) -> np.ndarray:
    """Curvature ``kappa = 2 tan(phi/2) / dl`` of every bending element (paper, E_b).

    Parameters
    ----------
    positions : ndarray, shape (N, 2)
        Node positions [m].
    bends : ndarray of int, shape (B, 3)
        Node triples (previous, middle, next).
    bend_length : ndarray, shape (B,)
        Voronoi length dl of each bending element [m].

    Returns
    -------
    ndarray, shape (B,)
        Signed curvature [1/m].
    """
    x = np.asarray(positions, dtype=float)
    e1 = x[bends[:, 1]] - x[bends[:, 0]]
    e2 = x[bends[:, 2]] - x[bends[:, 1]]
    return 2.0 * np.tan(0.5 * signed_turning_angle(e1, e2)) / bend_length


@dataclass
class RodNetwork:
    """Arrays that describe a planar rod network (all SI).

    Attributes
    ----------
    positions : ndarray, shape (N, 2)
        Reference node positions [m] (also the initial state).
    edges : ndarray of int, shape (E, 2)
        Stretching elements (node a, node b).
    edge_rest_length : ndarray, shape (E,)
        Rest length [m].
    edge_stretching_stiffness : ndarray, shape (E,)
        EA [N].
    edge_linear_density : ndarray, shape (E,)
        Structural mass per length [kg/m] (lumped half to each end node).
    edge_diameter : ndarray, shape (E,)
        Diameter D in the drag and added-mass laws (paper eq. 1, 3) [m].
    edge_drag_normal, edge_drag_tangent : ndarray, shape (E,)
        Drag coefficients C_n, C_t (paper eq. 2).
    bends : ndarray of int, shape (B, 3)
        Bending elements (node triples).
    bend_length : ndarray, shape (B,)
        Voronoi length dl of each bend [m] (mean of its two rest edge lengths).
    bend_stiffness : ndarray, shape (B,)
        EI [N m^2].
    bend_natural_curvature : ndarray, shape (B,)
        kappa0 [1/m].
    edge_group, bend_group : ndarray of int
        Free labels (e.g. 0 body, 1..4 limbs) for actuation and plotting.
    rods : list of ndarray
        Node index chains of the rods (for plotting).
    """

    positions: np.ndarray
    edges: np.ndarray
    edge_rest_length: np.ndarray
    edge_stretching_stiffness: np.ndarray
    edge_linear_density: np.ndarray
    edge_diameter: np.ndarray
    edge_drag_normal: np.ndarray
    edge_drag_tangent: np.ndarray
    bends: np.ndarray
    bend_length: np.ndarray
    bend_stiffness: np.ndarray
    bend_natural_curvature: np.ndarray
    edge_group: np.ndarray
    bend_group: np.ndarray
    rods: list = field(default_factory=list)

    @property
    def n_nodes(self) -> int:
        """Number of nodes N."""
        return self.positions.shape[0]

    @property
    def n_dof(self) -> int:
        """Number of degrees of freedom 2N."""
        return 2 * self.positions.shape[0]

    def validate(self) -> None:
        """Raise ``ValueError`` if an index or a value is out of range."""
        n = self.n_nodes
        if self.positions.ndim != 2 or self.positions.shape[1] != 2:
            raise ValueError(f'positions has shape {self.positions.shape}, expected (N, 2)')
        for name, idx in (('edges', self.edges), ('bends', self.bends)):
            if idx.size and (idx.min() < 0 or idx.max() >= n):
                raise ValueError(f'{name} refer to node {idx.max()} but the network has {n} nodes')
        for name in ('edge_rest_length', 'bend_length'):
            arr = getattr(self, name)
            if np.any(~np.isfinite(arr)) or np.any(arr <= 0):
                raise ValueError(f'{name} must be finite and > 0, got min {arr.min()!r}')
        for name in ('edge_stretching_stiffness', 'bend_stiffness', 'edge_linear_density',
                      'edge_diameter', 'edge_drag_normal', 'edge_drag_tangent'):
            arr = getattr(self, name)
            if np.any(~np.isfinite(arr)) or np.any(arr < 0):
                raise ValueError(f'{name} must be finite and >= 0')
        if np.any(self.bends[:, 0] == self.bends[:, 1]) or np.any(self.bends[:, 1] == self.bends[:, 2]):
            raise ValueError('a bending element repeats a node')


class RodNetworkBuilder:
    """Incremental construction of a :class:`RodNetwork`.

    Examples
    --------
    >>> b = RodNetworkBuilder()
    >>> ids = b.add_nodes([[0, 0], [0.01, 0], [0.02, 0]])
    >>> b.add_rod(ids, stretching_stiffness=10.0, bending_stiffness=1e-4,
    ...           linear_density=0.01, diameter=0.004, drag_normal=1.0, drag_tangent=0.01)
    >>> net = b.build()
    >>> net.n_nodes, len(net.edges), len(net.bends)
    (3, 2, 1)
    """

    def __init__(self):
        self._pos: list[list[float]] = []
        self._edges: list[tuple] = []   # (a, b, EA, rho_l, D, Cn, Ct, group)
        self._bends: list[tuple] = []   # (i, j, k, EI, kappa0 or None, group)
        self._rods: list[np.ndarray] = []

    def add_nodes(self, points) -> np.ndarray:
        """Append nodes at ``points`` (shape (n, 2), m); return their indices."""
        pts = np.atleast_2d(np.asarray(points, dtype=float))
        if pts.shape[1] != 2:
            raise ValueError(f'points have shape {pts.shape}, expected (n, 2)')
        start = len(self._pos)
        self._pos.extend(pts.tolist())
        return np.arange(start, start + len(pts))

    def add_edge(self, a, b, *, stretching_stiffness, linear_density, diameter, drag_normal,
                 drag_tangent, group=0):
        """Add one stretching element between nodes ``a`` and ``b``."""
        self._edges.append((int(a), int(b), float(stretching_stiffness), float(linear_density),
                            float(diameter), float(drag_normal), float(drag_tangent), int(group)))

    def add_bend(self, i, j, k, *, bending_stiffness, natural_curvature=None, group=0):
        """Add a bending element on the triple ``(i, j, k)``.

        ``natural_curvature=None`` takes kappa0 from the node positions at build time.
        """
        self._bends.append((int(i), int(j), int(k), float(bending_stiffness),
                            natural_curvature, int(group)))

    def add_rod(self, node_ids, *, stretching_stiffness, bending_stiffness, linear_density,
                diameter, drag_normal, drag_tangent, natural_curvature=None, closed=False,
                group=0):
        """Connect ``node_ids`` in order by edges and interior bends (optionally a closed loop)."""
        ids = [int(i) for i in node_ids]
        if len(ids) < 2:
            raise ValueError(f'a rod needs at least 2 nodes, got {len(ids)}')
        chain = ids + [ids[0]] if closed else ids
        for a, b in zip(chain[:-1], chain[1:]):
            self.add_edge(a, b, stretching_stiffness=stretching_stiffness,
                          linear_density=linear_density, diameter=diameter,
                          drag_normal=drag_normal, drag_tangent=drag_tangent, group=group)
        triples = [(chain[m - 1], chain[m], chain[m + 1]) for m in range(1, len(chain) - 1)]
        if closed:
            triples.append((ids[-1], ids[0], ids[1]))
        for t in triples:
            self.add_bend(*t, bending_stiffness=bending_stiffness,
                          natural_curvature=natural_curvature, group=group)
        self._rods.append(np.asarray(chain))

    def build(self) -> RodNetwork:
        """Freeze into a validated :class:`RodNetwork`."""
        pos = np.asarray(self._pos, dtype=float).reshape(-1, 2)
        e = self._edges
        edges = np.array([[t[0], t[1]] for t in e], dtype=np.int64).reshape(-1, 2)
        rest = np.linalg.norm(pos[edges[:, 1]] - pos[edges[:, 0]], axis=1)
        length_of = {}
        for (a, b), length in zip(edges.tolist(), rest):
            length_of[(a, b)] = length
            length_of[(b, a)] = length
        bends = np.array([[t[0], t[1], t[2]] for t in self._bends], dtype=np.int64).reshape(-1, 3)
        try:
            bend_len = np.array([0.5 * (length_of[(i, j)] + length_of[(j, k)])
                                 for i, j, k in bends.tolist()], dtype=float)
        except KeyError as err:
            raise ValueError(f'bend uses node pair {err.args[0]} that is not an edge') from None
        kappa_geom = discrete_curvature(pos, bends, bend_len) if len(bends) else np.zeros(0)
        kappa0 = np.array([kappa_geom[m] if t[4] is None else t[4]
                           for m, t in enumerate(self._bends)], dtype=float)
        net = RodNetwork(
            positions=pos, edges=edges, edge_rest_length=rest,
            edge_stretching_stiffness=np.array([t[2] for t in e], dtype=float),
            edge_linear_density=np.array([t[3] for t in e], dtype=float),
            edge_diameter=np.array([t[4] for t in e], dtype=float),
            edge_drag_normal=np.array([t[5] for t in e], dtype=float),
            edge_drag_tangent=np.array([t[6] for t in e], dtype=float),
            bends=bends, bend_length=bend_len,
            bend_stiffness=np.array([t[3] for t in self._bends], dtype=float),
            bend_natural_curvature=kappa0,
            edge_group=np.array([t[7] for t in e], dtype=np.int64),
            bend_group=np.array([t[5] for t in self._bends], dtype=np.int64),
            rods=list(self._rods))
        net.validate()
        return net


def straight_rod(n_edges: int, length: float, *, stretching_stiffness: float,
                 bending_stiffness: float, linear_density: float = 1.0, diameter: float = 0.004,
                 drag_normal: float = 1.0, drag_tangent: float = 0.01,
                 natural_curvature: float | None = None, start=(0.0, 0.0),
                 angle: float = 0.0) -> RodNetwork:
    """A straight open rod of ``n_edges`` equal edges (test and demo helper).

    Parameters
    ----------
    n_edges : int
        Number of edges (nodes = n_edges + 1).
    length : float
        Total length [m].
    angle : float
        Direction of the rod from ``start`` [rad].

    Returns
    -------
    RodNetwork
    """
    if n_edges < 1:
        raise ValueError(f'n_edges = {n_edges} must be >= 1')
    s = np.linspace(0.0, length, n_edges + 1)
    pts = np.column_stack([start[0] + s * np.cos(angle), start[1] + s * np.sin(angle)])
    b = RodNetworkBuilder()
    ids = b.add_nodes(pts)
    b.add_rod(ids, stretching_stiffness=stretching_stiffness, bending_stiffness=bending_stiffness,
              linear_density=linear_density, diameter=diameter, drag_normal=drag_normal,
              drag_tangent=drag_tangent, natural_curvature=natural_curvature)
    return b.build()
