"""The robot's outline for the renderer: body ring and limbs, in the body frame.

The simulator publishes its rod network as a list of segments (``frog/sim/shape``). The
body ring is what remains after repeatedly pruning the network's leaves (the limbs are
chains hanging from the ring's corners); its centroid is where the tag sits. Without a
simulator, :func:`frog_outline` builds the same topology from the robot's dimensions
(paper Fig. 2b: square body of side L_o = 90 mm, limbs of L_i = 35 mm at the corners).
"""
from __future__ import annotations

import dataclasses

import numpy as np

#: The robot's dimensions (paper Fig. 2b, as frog_sim reads them; see the README there).
BODY_SIDE = 0.090          # L_o: centre line of the square body [m]
BODY_FRAME_WIDTH = 0.0275  # in-plane width of the body frame (L_o - L_i) / 2 [m]
LIMB_LENGTH = 0.035        # L_i [m]
LIMB_WIDTH = 0.004         # limb rod diameter [m]
LIMB_ROOT_ANGLE = np.radians(-75.0)   # root direction from lateral toward aft
#: Centre of mass relative to the body ring's centre, along the body's x axis [m]. Measured on
#: frog_sim's calibrated model (its rigid-body centre includes the limbs' added mass, eq. 10)
#: at the default design over a 1 Hz gait, in the frame of its heading: 3.36 +- 0.31 mm AHEAD
#: of the ring's centre. It is
#: also the default tag-to-body offset (the tag is glued on the body's centre).
COM_AHEAD_OF_RING_CENTRE = 0.00336


@dataclasses.dataclass(frozen=True)
class RobotShape:
    """Body ring polygon (M, 2) in order and limb segments (K, 2, 2), body frame [m]."""

    ring: np.ndarray
    limbs: np.ndarray

    @property
    def ring_centre(self) -> np.ndarray:
        """Centroid of the ring's nodes [m]: the tag's position."""
        return self.ring.mean(axis=0)

    def transformed(self, pose) -> "RobotShape":
        """The shape moved by a planar pose (x, y, yaw)."""
        c, s = np.cos(pose[2]), np.sin(pose[2])
        r = np.array([[c, s], [-s, c]])
        t = np.asarray(pose[:2], float)
        return RobotShape(self.ring @ r + t, self.limbs @ r + t)


def shape_from_segments(segments) -> RobotShape:
    """Split a rod network (segments (E, 2, 2), shared end points) into ring and limbs.

    Raises
    ------
    ValueError
        The network has no closed ring.
    """
    seg = np.asarray(segments, float).reshape(-1, 2, 2)
    if len(seg) == 0:
        raise ValueError("the shape has no segments")
    keys = np.round(seg.reshape(-1, 2) * 1e7).astype(np.int64)
    uniq, inverse = np.unique(keys, axis=0, return_inverse=True)
    pts = uniq / 1e7
    edges = inverse.reshape(-1, 2)
    n = len(pts)
    adj = [set() for _ in range(n)]
    for a, b in edges:
        if a != b:
            adj[a].add(b)
            adj[b].add(a)
    alive = np.ones(n, bool)
    leaves = [i for i in range(n) if len(adj[i]) <= 1]
    deg = np.array([len(a) for a in adj])
    while leaves:
        i = leaves.pop()
        if not alive[i]:
            continue
        alive[i] = False
        for j in adj[i]:
            if alive[j]:
                deg[j] -= 1
                if deg[j] <= 1:
                    leaves.append(j)
    ring_nodes = np.flatnonzero(alive)
    if len(ring_nodes) < 3:
        raise ValueError("the shape has no closed body ring")
    start = ring_nodes[0]
    order, prev, cur = [start], -1, start
    while True:
        nxt = [j for j in adj[cur] if alive[j] and j != prev]
        if not nxt or nxt[0] == start:
            break
        prev, cur = cur, nxt[0]
        order.append(cur)
        if len(order) > len(ring_nodes):
            break
    ring_set = set(ring_nodes.tolist())
    limb_edges = [e for e in edges if not (e[0] in ring_set and e[1] in ring_set)]
    limbs = pts[np.array(limb_edges)].reshape(-1, 2, 2) if limb_edges else np.zeros((0, 2, 2))
    return RobotShape(pts[order], limbs)


def frog_outline(limb_curl: float = 0.0, edges_per_side: int = 23, limb_edges: int = 9) -> RobotShape:
    """The robot's rod network at rest in the body frame (origin at the centre of mass, so
    the ring's centre is ``COM_AHEAD_OF_RING_CENTRE`` behind it).

    Parameters
    ----------
    limb_curl : float
        Curvature of every limb [1/m] (positive curls the tips toward the body axis).
    """
    h = BODY_SIDE / 2
    corners = np.array([[h, h], [-h, h], [-h, -h], [h, -h]])
    ring = np.concatenate([np.linspace(corners[i], corners[(i + 1) % 4], edges_per_side,
                                       endpoint=False) for i in range(4)])
    limbs = []
    ds = LIMB_LENGTH / limb_edges
    for cx, cy in corners:
        side = np.sign(cy)                      # left limbs point to +y, right to -y
        ang = side * (np.pi / 2 - LIMB_ROOT_ANGLE)   # lateral, turned aft by the root angle
        p = np.array([cx, cy])
        for _ in range(limb_edges):
            q = p + ds * np.array([np.cos(ang), np.sin(ang)])
            limbs.append([p, q])
            p = q
            ang += side * limb_curl * ds
    shift = np.array([-COM_AHEAD_OF_RING_CENTRE, 0.0])
    return RobotShape(ring + shift, np.array(limbs) + shift)
