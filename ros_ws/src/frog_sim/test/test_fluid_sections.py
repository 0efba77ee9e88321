"""Fluid sections: body drag/added mass from the body's height, limb strip width, kick geometry."""
import numpy as np
import pytest

from frog_sim.core.fluid import drag_forces, drag_prefactors
from frog_sim.core.frog_model import BODY_GROUP, build_frog_model
from frog_sim.core.model_parameters import FrogParameters

PHYS = dict(body_fluid_section="height", added_mass_lumping="direction_average")


def test_body_sections_follow_fig2b_heights():
    p = FrogParameters().replace(**PHYS)
    net = build_frog_model(p).network
    body = net.edge_group == BODY_GROUP
    a, b = net.positions[net.edges[:, 0]], net.positions[net.edges[:, 1]]
    mid = 0.5 * (a + b)
    half = p.body_side_length / 2
    front = body & np.isclose(mid[:, 0], half)
    rear = body & np.isclose(mid[:, 0], -half)
    assert front.sum() == rear.sum() == p.body_edges_per_side
    assert np.allclose(net.edge_diameter[front], p.front_dimension_hf)
    assert np.allclose(net.edge_diameter[rear], p.aft_dimension_ha)
    side = body & ~front & ~rear
    expected = p.aft_dimension_ha + (p.front_dimension_hf - p.aft_dimension_ha) * (mid[side, 0] + half) / (2 * half)
    assert np.allclose(net.edge_diameter[side], expected)
    # the legacy rod section is unchanged
    legacy = build_frog_model(FrogParameters(body_fluid_section="rod")).network
    assert np.allclose(legacy.edge_diameter[legacy.edge_group == BODY_GROUP], 0.004)


def test_body_drag_of_a_rigid_translation_by_hand():
    """u along x: front and rear sides normal (C_bn), the two sides tangential (C_bt), eq. 1."""
    p = FrogParameters().replace(**PHYS)
    net = build_frog_model(p).network
    body = np.nonzero(net.edge_group == BODY_GROUP)[0]
    cn, ct = drag_prefactors(net, p.fluid_density)
    u = 0.03
    v = np.tile([u, 0.0], net.n_nodes)
    f = np.zeros(2 * net.n_nodes)
    drag_forces(net.positions.ravel(), v, net.edges[body], cn[body], ct[body], f)
    L, rho = p.body_side_length, p.fluid_density
    mean_h = 0.5 * (p.front_dimension_hf + p.aft_dimension_ha)
    expected = -0.5 * rho * u * u * (p.body_drag_normal * L * (p.front_dimension_hf + p.aft_dimension_ha)
                                     + p.body_drag_tangent * 2 * L * mean_h)
    assert f[0::2].sum() == pytest.approx(expected, rel=1e-9)
    assert abs(f[1::2].sum()) < 1e-12


def test_added_mass_lumping_and_limb_width_by_hand():
    base = FrogParameters().replace(body_fluid_section="height", limb_fluid_width=0.012, added_mass_lumping="normal")
    m_normal = build_frog_model(base)
    m_avg = build_frog_model(base.replace(added_mass_lumping="direction_average"))
    net = m_normal.network
    structural = float(np.sum(net.edge_linear_density * net.edge_rest_length))
    added = float(np.sum(np.pi * net.edge_diameter ** 2 / 4 * net.edge_rest_length)) * base.fluid_density
    assert m_normal.total_mass == pytest.approx(structural + added, rel=1e-12)
    assert m_avg.total_mass == pytest.approx(structural + 0.5 * added, rel=1e-12)
    limb = net.edge_group != BODY_GROUP
    assert np.allclose(net.edge_diameter[limb], 0.012)
    # body added mass of a translating square ring: two sides of height H normal to the motion
    L = base.body_side_length
    body_added_avg = 0.5 * float(np.sum((np.pi * net.edge_diameter ** 2 / 4 * net.edge_rest_length)[~limb])) * 1000
    ring = 1000 * np.pi / 4 * L * (base.front_dimension_hf ** 2 + base.aft_dimension_ha ** 2)
    assert body_added_avg == pytest.approx(ring, rel=0.06)    # the sides' mean H^2 vs the front/rear H^2


def test_front_root_offset_turns_only_the_front_limbs():
    p0 = FrogParameters(front_root_angle_offset_deg=0.0)
    p1 = p0.replace(front_root_angle_offset_deg=40.0)
    m0, m1 = build_frog_model(p0), build_frog_model(p1)

    def first_edge_angle(model, limb):
        corner = model.network.positions[model.corner_nodes[limb]]
        tip = model.network.positions[model.limb_nodes[limb][0]]
        d = tip - corner
        return np.degrees(np.arctan2(d[1], d[0]))
    for limb, sign in (("FL", -1.0), ("FR", 1.0)):
        turned = (first_edge_angle(m1, limb) - first_edge_angle(m0, limb) + 180.0) % 360.0 - 180.0
        assert turned == pytest.approx(sign * 40.0, abs=1e-9)    # toward the front on both sides
    for limb in ("BL", "BR"):
        assert first_edge_angle(m1, limb) == pytest.approx(first_edge_angle(m0, limb), abs=1e-12)
    # mirror symmetry of the built robot about the x axis
    pos = m1.network.positions
    for a, b in (("FL", "FR"), ("BL", "BR")):
        pa, pb = pos[m1.limb_nodes[a]], pos[m1.limb_nodes[b]]
        assert np.allclose(pa[:, 0], pb[:, 0]) and np.allclose(pa[:, 1], -pb[:, 1])
