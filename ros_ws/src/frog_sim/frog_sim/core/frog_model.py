"""Builder of the square frog robot of paper Fig. 2 as a rod network.

Layout (robot frame ``frog``: x forward, y left, origin at the body centre):

* body: a closed ring of four stiff rods, side ``L_o``, ``n`` edges per side; ring nodes
  run counter-clockwise from the front-right corner: FR = 0, FL = n, BL = 2n, BR = 3n.
  The corner turning angles (90 deg) are the body's natural curvature.
* limbs FL, FR, BL, BR: one rod of ``L_i`` per corner. Each corner node joins three
  edges and carries two bending energies (body corner + limb root), paper "Energy ...".
  The root direction is the lateral direction turned toward the rear by
  ``-limb_root_angle_deg`` (rear limbs; default -90 deg: straight aft), the front limbs
  ``front_root_angle_offset_deg`` further forward (default 32: 58 deg aft of lateral).
  Fig. 2b gives no angle; both were calibrated jointly against the hardware turning
  transitions and the speed experiments (``frog-sweep calibrate``).
* Fluid sections: the body's edges take its height as D in eq. 1 and 3 (H_f at the front
  side to H_a at the rear, linear along the sides); the limb edges the strip width
  ``limb_fluid_width``.
  The root bend (body side edge -> first limb edge) is the clamp of the limb: only
  its limb half cell bends, so its stiffness is 2 E(t) I (rigid body half in series),
  and it carries the limb curvature of that half cell, so that the whole limb length
  is curved (the polygon is inscribed in an arc tangent to the root direction). The
  limb's interior bends are actuated: natural curvature ``sign * kappa(t)`` (eq. 9),
  stiffness ``E(t) I``. Relaxed aft-pointing limbs curl away from the body axis
  (``limb_curl_direction = 'forward'``, calibrated; ``'backward'`` curls them
  toward it); the fast unrolling kick drives the robot forward (+x), the slow
  re-curling (recovery) costs less because drag is quadratic.
* No contact is modelled; a curled rear limb may overlap the body in the plane (in
  the robot the limbs sit below the foam body).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .actuation import ActuatorArrays, CurvatureProfile
from .fluid import lumped_masses
from .model_parameters import FrogParameters
from .rigid_body import center_of_mass
from .rod_network import RodNetwork, RodNetworkBuilder
from frog_common.primitives import LIMB_IDS, LIMB_NAMES

BODY_GROUP = 0


def limb_group(limb: str) -> int:
    """Element group id of a limb (body is 0)."""
    return LIMB_IDS[limb] + 1


@dataclass
class FrogModel:
    """A built frog: rod network, masses and the bookkeeping of its limbs.

    Attributes
    ----------
    params : FrogParameters
    network : RodNetwork
    mass : ndarray, shape (N,)
        Revised lumped masses incl. added mass [kg] (eq. 4).
    corner_nodes : dict
        Limb name -> joint node index.
    limb_nodes : dict
        Limb name -> node indices from the joint (excluded) to the tip.
    limb_bends : dict
        Limb name -> indices of its actuated bending elements.
    limb_edges : dict
        Limb name -> indices of its edges.
    limb_sign : dict
        Limb name -> +1/-1 (kappa0 = sign * kappa(t)).
    reference_pose : ndarray, shape (N, 2)
        Unactuated pose with its centre of mass at the origin [m] (eq. 11).
    root_bends : dict
        Limb name -> index of its root bend (body side edge -> first limb edge).
    root_base_angle : dict
        Limb name -> turning angle of the root bend for a straight limb [rad].
    """

    params: FrogParameters
    network: RodNetwork
    mass: np.ndarray
    corner_nodes: dict
    limb_nodes: dict
    limb_bends: dict
    limb_edges: dict
    limb_sign: dict
    reference_pose: np.ndarray
    root_bends: dict = None
    root_base_angle: dict = None

    @property
    def n_nodes(self) -> int:
        """Number of nodes."""
        return self.network.n_nodes

    @property
    def total_mass(self) -> float:
        """Sum of the revised nodal masses [kg]."""
        return float(self.mass.sum())

    def actuator_arrays(self, profiles) -> ActuatorArrays:
        """Numba arrays driving the four limbs with ``profiles`` (one per limb or a single one).

        Parameters
        ----------
        profiles : CurvatureProfile or sequence of 4 CurvatureProfile
            In limb-id order FL, FR, BL, BR when a sequence.
        """
        if isinstance(profiles, CurvatureProfile):
            profiles = [profiles] * len(LIMB_NAMES)
        if len(profiles) != len(LIMB_NAMES):
            raise ValueError(f'need {len(LIMB_NAMES)} profiles, got {len(profiles)}')
        p = self.params
        bend_index, bend_limb, bend_sign, edge_index, edge_limb = [], [], [], [], []
        for limb in LIMB_NAMES:
            lid = LIMB_IDS[limb]
            bend_index += list(self.limb_bends[limb])
            bend_limb += [lid] * len(self.limb_bends[limb])
            bend_sign += [self.limb_sign[limb]] * len(self.limb_bends[limb])
            edge_index += list(self.limb_edges[limb])
            edge_limb += [lid] * len(self.limb_edges[limb])
        arr = ActuatorArrays(
            limb_profile=np.array([prof.as_row() for prof in profiles]),
            limb_young=np.tile([p.limb_young_relaxed, p.limb_young_heated], (len(LIMB_NAMES), 1)),
            activation_times=np.zeros(0), activation_offsets=np.zeros(len(LIMB_NAMES) + 1, dtype=np.int64),
            bend_index=np.array(bend_index, dtype=np.int64),
            bend_limb=np.array(bend_limb, dtype=np.int64),
            bend_sign=np.array(bend_sign, dtype=float),
            bend_second_moment=np.full(len(bend_index), p.limb_second_moment),
            edge_index=np.array(edge_index, dtype=np.int64),
            edge_limb=np.array(edge_limb, dtype=np.int64),
            edge_area=np.full(len(edge_index), p.limb_area),
            root_index=np.array([self.root_bends[l] for l in LIMB_NAMES], dtype=np.int64),
            root_limb=np.array([LIMB_IDS[l] for l in LIMB_NAMES], dtype=np.int64),
            root_sign=np.array([self.limb_sign[l] for l in LIMB_NAMES], dtype=float),
            root_base_angle=np.array([self.root_base_angle[l] for l in LIMB_NAMES]),
            root_half_edge=np.full(len(LIMB_NAMES), 0.5 * p.edge_length),
            root_length=self.network.bend_length[[self.root_bends[l] for l in LIMB_NAMES]],
            root_second_moment=np.full(len(LIMB_NAMES), 2.0 * p.limb_second_moment))
        return arr


def _limb_points(root, direction, n_edges, dl, turning):
    """Nodes of a discrete arc tangent to ``direction`` at ``root``: chord k points along
    the direction turned by (k + 1/2) ``turning`` (the polygon inscribed in the arc)."""
    pts = []
    ang = np.arctan2(direction[1], direction[0]) + 0.5 * turning
    p = np.asarray(root, dtype=float)
    for k in range(n_edges):
        if k > 0:
            ang += turning
        p = p + dl * np.array([np.cos(ang), np.sin(ang)])
        pts.append(p)
    return np.array(pts)


def build_frog_model(params: FrogParameters | None = None, relaxed_curvature: float = 125.0) -> FrogModel:
    """Build the frog robot rod network (paper Fig. 2).

    Parameters
    ----------
    params : FrogParameters, optional
        Physical parameters (defaults: :class:`FrogParameters`).
    relaxed_curvature : float
        Curvature of the unactuated limbs in the built (reference) pose [1/m]; use the
        relaxed curvature of the actuation profile so that the model starts at rest.

    Returns
    -------
    FrogModel

    Examples
    --------
    >>> model = build_frog_model()
    >>> model.n_nodes
    128
    """
    p = params or FrogParameters()
    p.validate()
    if not np.isfinite(relaxed_curvature) or relaxed_curvature < 0:
        raise ValueError(f'relaxed_curvature = {relaxed_curvature!r} 1/m must be finite and >= 0')
    n = int(p.body_edges_per_side)
    side = p.body_side_length
    dl = p.edge_length
    half = side / 2
    corners = np.array([[half, -half], [half, half], [-half, half], [-half, -half]])  # FR, FL, BL, BR
    ring = []
    for c in range(4):
        a, b = corners[c], corners[(c + 1) % 4]
        for k in range(n):
            ring.append(a + (b - a) * k / n)
    ring = np.array(ring)
    builder = RodNetworkBuilder()
    ring_ids = builder.add_nodes(ring)
    body_kw = dict(stretching_stiffness=p.body_stretching_stiffness,
                   linear_density=p.body_linear_density, diameter=p.body_rod_diameter,
                   drag_normal=p.body_drag_normal, drag_tangent=p.body_drag_tangent)
    builder.add_rod(ring_ids, bending_stiffness=p.body_bending_stiffness, closed=True,
                    group=BODY_GROUP, **body_kw)
    n_ring = len(ring_ids)
    corner_of = {'FR': 0, 'FL': n, 'BL': 2 * n, 'BR': 3 * n}
    # (neighbour on the front/rear side, outward direction, sign of a forward curl)
    layout = {'FL': (n - 1, (0.0, 1.0), -1), 'FR': (1, (0.0, -1.0), +1),
              'BL': (2 * n + 1, (0.0, 1.0), -1), 'BR': (3 * n - 1, (0.0, -1.0), +1)}
    curl = 1.0 if p.limb_curl_direction == 'forward' else -1.0
    n_limb = p.limb_edges
    turning = 2.0 * np.arctan(0.5 * relaxed_curvature * dl)  # kappa = 2 tan(phi/2)/dl
    limb_kw = dict(stretching_stiffness=p.limb_young_relaxed * p.limb_area,
                   linear_density=p.limb_density * p.limb_area, diameter=p.limb_fluid_width,
                   drag_normal=p.limb_drag_normal, drag_tangent=p.limb_drag_tangent)
    limb_nodes, limb_sign, bend_ranges, edge_ranges, root_bends, root_base = {}, {}, {}, {}, {}, {}
    for limb in LIMB_NAMES:
        corner = corner_of[limb]
        side_nb, direction, sign = layout[limb]
        sign = int(sign * curl)
        # turn the lateral direction by the root angle (negative: toward the rear)
        root_deg = p.limb_root_angle_deg + (p.front_root_angle_offset_deg if limb in ('FL', 'FR') else 0.0)
        aft = np.radians(root_deg) * (-1.0 if direction[1] > 0 else 1.0)
        direction = (np.cos(aft) * direction[0] - np.sin(aft) * direction[1],
                     np.sin(aft) * direction[0] + np.cos(aft) * direction[1])
        pts = _limb_points(ring[corner], direction, n_limb, dl, sign * turning)
        ids = builder.add_nodes(pts)
        e0 = len(builder._edges)
        b0 = len(builder._bends)
        builder.add_rod([corner, *ids], bending_stiffness=p.limb_young_relaxed * p.limb_second_moment,
                        natural_curvature=sign * relaxed_curvature, group=limb_group(limb),
                        **limb_kw)
        edge_ranges[limb] = np.arange(e0, len(builder._edges))
        bend_ranges[limb] = np.arange(b0, len(builder._bends))
        # root bend: body side edge -> first limb edge (passive, strapped to the body)
        builder.add_bend(side_nb, corner, ids[0],
                         bending_stiffness=2.0 * p.limb_young_relaxed * p.limb_second_moment,
                         group=BODY_GROUP)
        root_bends[limb] = len(builder._bends) - 1
        root_base[limb] = _turning(ring[side_nb], ring[corner], np.asarray(ring[corner]) + direction)
        limb_nodes[limb] = ids
        limb_sign[limb] = sign
    network = builder.build()
    if p.body_fluid_section == 'height':
        # the body's sides are H_f (front) to H_a (rear) tall: D of eq. 1 and 3 (Fig. 2b)
        body = network.edge_group == BODY_GROUP
        mid_x = 0.5 * (network.positions[network.edges[:, 0], 0] + network.positions[network.edges[:, 1], 0])
        share = np.clip((mid_x + half) / side, 0.0, 1.0)
        network.edge_diameter[body] = (p.aft_dimension_ha
                                       + (p.front_dimension_hf - p.aft_dimension_ha) * share[body])
    lumping = 0.5 if p.added_mass_lumping == 'direction_average' else 1.0
    mass = lumped_masses(network, p.fluid_density, p.added_mass_coefficient, lumping_factor=lumping)
    pose = network.positions - center_of_mass(network.positions, mass)
    assert n_ring == 4 * n
    return FrogModel(params=p, network=network, mass=mass, corner_nodes=corner_of,
                     limb_nodes=limb_nodes, limb_bends=bend_ranges, limb_edges=edge_ranges,
                     limb_sign=limb_sign, reference_pose=pose, root_bends=root_bends,
                     root_base_angle=root_base)


def _turning(a, b, c) -> float:
    """Signed turning angle at b of the polyline a -> b -> c [rad]."""
    e1 = np.asarray(b) - np.asarray(a)
    e2 = np.asarray(c) - np.asarray(b)
    return float(np.arctan2(e1[0] * e2[1] - e1[1] * e2[0], e1 @ e2))
