"""Pneumatic chambers, DEA prisms, calibration (eq. 7-8, 16, 18-19) and mesh I/O."""
import numpy as np
import pytest

from softkin_fk.core.calibration import (calibrate_shape_parameter, simulated_elasticity_ratio,
                                         volume_ratio_from_pressure)
from softkin_fk.core.forward import ForwardSolver
from softkin_fk.core.mesh import (prism_volumes, read_tetgen, read_volume_mesh, tet_volumes, triangle_areas,
                                  write_tetgen, write_volume_mesh)
from softkin_fk.core.meshing import tetgen_box
from softkin_fk.core.models import build_dea_crawler, build_pneumatic_actuator


@pytest.mark.parametrize('alpha', [1.3, 2.0])
def test_pneumatic_chamber_volume_reaches_target(alpha):
    """Enforced actuation: the chamber's volume ratio equals alpha (eq. 8) to 1e-4, and the
    actuator bends away from the inflated chamber (chamber 0 lies towards +y)."""
    m = build_pneumatic_actuator(1, n_chambers=1, length_mm=80)
    g = m.group('chamber_0')
    v0 = tet_volumes(m.vertices, g.elements).sum()
    res = ForwardSolver(m).solve([alpha], tol=1e-8, enforce_constraints=True, constraint_tol=1e-6)
    ratio = tet_volumes(res.positions, g.elements).sum() / v0
    assert ratio == pytest.approx(alpha, rel=1e-4)
    tip_move = res.marker(m) - m.vertices[m.markers['tip']]
    assert tip_move[1] < -1e-3 and abs(tip_move[2]) < 0.1 * abs(tip_move[1])  # grid split is not z-symmetric


def test_dea_area_ratio_and_volume():
    """DEA prisms reach the commanded area ratio (eq. 7) while their volume stays within 3 %,
    and the free frame moves forward."""
    c = build_dea_crawler(1)
    g = c.group('dea')

    def area(x):
        e = g.elements
        return 0.5 * (triangle_areas(x, e[:, :3]) + triangle_areas(x, e[:, 3:])).sum()

    a0, v0 = area(c.vertices), prism_volumes(c.vertices, g.elements).sum()
    res = ForwardSolver(c).solve([1.3], tol=1e-9, enforce_constraints=True, constraint_tol=1e-6)
    assert area(res.positions) / a0 == pytest.approx(1.3, rel=1e-4)
    assert prism_volumes(res.positions, g.elements).sum() / v0 == pytest.approx(1.0, abs=0.03)
    assert res.marker(c)[0] - c.vertices[c.markers['tip'], 0] > 2e-3


def test_ideal_gas_volume_ratio_inverts_eq18():
    """eq. 19 returns the alpha used to generate a syringe reading from eq. 18."""
    Pa, Vc0, Vsy0, Vt = 100e3, 20e-6, 30e-6, 2e-6
    for alpha, P in ((1.0, 100e3), (1.4, 150e3), (2.1, 240e3)):
        dV = Vc0 * alpha + Vsy0 + Vt - Pa * (Vc0 + Vsy0 + Vt) / P   # solve eq. 18 for dV_sy
        assert volume_ratio_from_pressure(P, dV, Vc0, Vsy0, Vt) == pytest.approx(alpha, rel=1e-12)
    with pytest.raises(ValueError, match='positive'):
        volume_ratio_from_pressure(-1.0, 0.0, Vc0, Vsy0, Vt)


@pytest.mark.slow
def test_equal_materials_give_unit_elasticity_ratio_and_calibration_is_monotone():
    assert simulated_elasticity_ratio(1.0, 1.0) == pytest.approx(1.0, rel=1e-6)
    soft = calibrate_shape_parameter(5.68, rel_tol=1e-2)
    stiff = calibrate_shape_parameter(3.75, rel_tol=1e-2)
    assert soft.achieved == pytest.approx(5.68, rel=1e-2)
    assert soft.ratio > stiff.ratio > 1.0
    with pytest.raises(ValueError, match='must exceed 1'):
        calibrate_shape_parameter(0.5)


def test_mesh_io_roundtrip(tmp_path):
    v, t = tetgen_box((0.02, 0.01, 0.01), max_volume=2e-8)
    assert tet_volumes(v, t).sum() == pytest.approx(2e-6, rel=1e-9)
    write_tetgen(str(tmp_path / 'box'), v, t)
    v2, t2 = read_tetgen(str(tmp_path / 'box'))
    assert np.allclose(v2, v) and np.array_equal(t2, t)
    m = read_volume_mesh(str(tmp_path / 'box.node'), fixed=[0])
    write_volume_mesh(str(tmp_path / 'box.vtu'), m)
    m2 = read_volume_mesh(str(tmp_path / 'box.vtu'), scale=1.0)
    assert m2.n_tets == len(t)
    assert tet_volumes(m2.vertices, m2.tets).sum() == pytest.approx(2e-6, rel=1e-9)
    with pytest.raises(FileNotFoundError):
        read_volume_mesh(str(tmp_path / 'missing.vtu'))
