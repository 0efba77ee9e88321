"""User meshes: mesh file + JSON spec -> SoftMesh, through the library and the ``softkin`` CLI."""
import copy
import json
import os

import numpy as np
import pytest

from softkin_fk.cli import main
from softkin_fk.core.forward import ForwardSolver
from softkin_fk.core.mesh import read_tetgen, read_volume_mesh, write_tetgen
from softkin_fk.core.mesh_spec import MeshSpecError, export_mesh_with_spec, load_mesh_with_spec
from softkin_fk.core.models import build_dea_crawler, build_pneumatic_actuator, build_tendon_finger

EXAMPLES = os.path.join(os.path.dirname(__file__), '..', 'examples')
EX_MESH = os.path.join(EXAMPLES, 'finger_mm.msh')
EX_SPEC = os.path.join(EXAMPLES, 'finger_mm.json')
#: FK is solved to 1e-9 m in these tests; identical robots agree far below that
TIP_TOL = 1e-9


def _fk_cli(tmp_path, name, args):
    out = tmp_path / name
    rc = main(['fk', *args, '--tol', '1e-10', '--out', str(out), '--quiet'])
    assert rc == 0
    return json.loads((out / 'result.json').read_text())


def _same_groups(a, b, body_name=None):
    """Same element groups (as sets of elements), fixed vertices, markers and actuators."""
    names = [g.name for g in a.groups]
    if body_name:
        names = [body_name if n == 'body' else n for n in names]
    assert names == [g.name for g in b.groups]
    for ga, gb in zip(a.groups, b.groups):
        assert ga.kind == gb.kind and ga.weight == gb.weight and ga.thickness == pytest.approx(gb.thickness)
        assert set(map(tuple, ga.elements)) == set(map(tuple, gb.elements)), ga.name
        assert np.allclose(ga.shape_parameter, gb.shape_parameter)
    assert np.array_equal(a.fixed, b.fixed) and a.markers == b.markers
    for aa, ab in zip(a.actuators, b.actuators):
        assert aa.name == ab.name and aa.segment_multiplicity == ab.segment_multiplicity
        assert aa.total_length == pytest.approx(ab.total_length) and np.allclose(aa.bounds, ab.bounds)


def test_example_gmsh_model_through_cli_matches_builtin_finger(tmp_path):
    """The shipped gmsh example (mm, physical names, cable polylines, fixed base surface, tip
    point) is the resolution-1 finger: same groups, and FK through ``softkin fk --mesh --spec``
    gives the built-in model's deformed tip."""
    user = load_mesh_with_spec(EX_MESH, EX_SPEC)
    _same_groups(build_tendon_finger(resolution=1), user, body_name='finger')
    act = ['--actuation', '0.96', '0.98', '0.97']
    ref = _fk_cli(tmp_path, 'builtin', ['--resolution', '1', *act])
    got = _fk_cli(tmp_path, 'user', ['--mesh', EX_MESH, '--spec', EX_SPEC, *act])
    tip_ref, tip = np.array(ref['markers']['tip']), np.array(got['markers']['tip'])
    assert np.linalg.norm(tip_ref - np.array([0.12, 0.025, 0.0125])) > 5e-3  # really bent
    assert np.linalg.norm(tip - tip_ref) < TIP_TOL
    assert got['converged'] and got['n_tets'] == ref['n_tets']


def test_spec_selectors_box_plane_point_elements_and_gaps():
    """Other ways to say the same thing: fixed by a box or a plane, tip by a point, the body by
    element indices, explicit gap segments -- all give the same robot."""
    spec = json.load(open(EX_SPEC))
    ref = load_mesh_with_spec(EX_MESH, spec)
    variants = []
    s = copy.deepcopy(spec)
    s['fixed'] = [{'box': [[-1, -1, -1], [0.001, 26, 26]]}]
    s['markers'] = {'tip': {'point': [120.2, 25.1, 12.5]}}
    variants.append(s)
    s = copy.deepcopy(spec)
    s['fixed'] = [{'plane': {'point': [0, 0, 0], 'normal': [2, 0, 0]}}]
    s['regions'] = [{'name': 'finger', 'cells': {'elements': list(range(1152))}, 'shape_parameter': 1.0}]
    for a in s['actuators']:
        a['gaps'] = [0, 2]
    variants.append(s)
    for s in variants:
        _same_groups(ref, load_mesh_with_spec(EX_MESH, s))
    # unclaimed volume cells fall into a default 'body' region with default_shape_parameter
    s = copy.deepcopy(spec)
    del s['regions']
    s['default_shape_parameter'] = 0.4
    m = load_mesh_with_spec(EX_MESH, s)
    assert m.groups[0].name == 'body' and np.all(m.groups[0].shape_parameter == 0.4)


@pytest.mark.parametrize('ext, units', [('.msh', 'm'), ('.vtu', 'mm')])
def test_export_round_trip_pneumatic_through_cli(tmp_path, ext, units):
    """``softkin export`` writes a built-in model as mesh + spec; ``softkin fk --mesh --spec``
    on those files gives the built-in model's deformed shape (chamber 0 inflated)."""
    path = str(tmp_path / f'pneu{ext}')
    assert main(['export', '--model', 'pneumatic', '--mesh-out', path, '--units', units]) == 0
    spec = json.load(open(str(tmp_path / 'pneu.json')))
    assert spec['units'] == units and [a['type'] for a in spec['actuators']] == ['pneumatic'] * 3
    act = ['--actuation', '1.6', '1', '1']
    ref = _fk_cli(tmp_path, 'builtin', ['--model', 'pneumatic', *act])
    got = _fk_cli(tmp_path, 'user', ['--mesh', path, '--spec', str(tmp_path / 'pneu.json'), *act])
    tip_ref, tip = np.array(ref['markers']['tip']), np.array(got['markers']['tip'])
    assert np.linalg.norm(tip_ref - np.array([0.136, 0, 0])) > 2e-3
    assert np.linalg.norm(tip - tip_ref) < TIP_TOL


def test_export_round_trip_finger_cables_as_triangle_cells(tmp_path):
    """Cable triangles stored as a physical group of triangles (``"cells"``) load back exactly."""
    m = build_tendon_finger(resolution=1)
    path = str(tmp_path / 'finger.msh')
    export_mesh_with_spec(m, path, units='mm')
    user = load_mesh_with_spec(path, str(tmp_path / 'finger.json'))
    _same_groups(m, user)
    c = np.array([0.95, 1.0, 0.97])
    a, b = ForwardSolver(m).solve(c, tol=1e-10), ForwardSolver(user).solve(c, tol=1e-10)
    assert np.linalg.norm(a.marker(m) - b.marker(user)) < TIP_TOL


def test_export_round_trip_dea_prism_mesh(tmp_path):
    """A prism (wedge) shell with two body regions of different R_w and a DEA membrane."""
    m = build_dea_crawler()
    path = str(tmp_path / 'dea.msh')
    export_mesh_with_spec(m, path, units='mm')
    user = load_mesh_with_spec(path, str(tmp_path / 'dea.json'))
    _same_groups(m, user)
    c = np.array([1.4])
    a, b = ForwardSolver(m).solve(c, tol=1e-10), ForwardSolver(user).solve(c, tol=1e-10)
    assert np.linalg.norm(a.marker(m) - m.vertices[m.markers['tip']]) > 1e-3
    assert np.linalg.norm(a.marker(m) - b.marker(user)) < TIP_TOL


def test_tetgen_round_trip(tmp_path):
    """TetGen .node/.ele with region attributes: raw I/O round trip, then a pneumatic actuator
    written as .node/.ele + spec loads to the same robot and the same FK."""
    m = build_pneumatic_actuator(resolution=1)
    base = str(tmp_path / 'raw')
    attr = np.arange(m.n_tets) % 3 + 1
    write_tetgen(base, m.vertices, m.tets, attributes=attr)
    v, t, a = read_tetgen(base, return_attributes=True)
    assert np.array_equal(v, m.vertices) and np.array_equal(t, m.tets) and np.array_equal(a, attr)
    v2, t2 = read_tetgen(base)
    assert np.array_equal(t2, m.tets)
    assert read_volume_mesh(base + '.ele', scale=1.0).n_tets == m.n_tets

    path = str(tmp_path / 'pneu.node')
    export_mesh_with_spec(m, path, units='mm')
    assert os.path.exists(str(tmp_path / 'pneu.ele'))
    user = load_mesh_with_spec(path, str(tmp_path / 'pneu.json'))
    _same_groups(m, user)
    c = np.array([1.0, 1.8, 1.0])
    r1, r2 = ForwardSolver(m).solve(c, tol=1e-10), ForwardSolver(user).solve(c, tol=1e-10)
    assert np.linalg.norm(r1.marker(m) - r2.marker(user)) < TIP_TOL
    with pytest.raises(MeshSpecError, match='tetrahedra only'):
        export_mesh_with_spec(build_tendon_finger(resolution=1), str(tmp_path / 'f.node'))


def _bad(tmp_path, capsys, args):
    rc = main(['fk', *args, '--out', str(tmp_path / 'bad'), '--quiet'])
    err = capsys.readouterr().err
    assert rc == 2, err
    return err


def test_bad_user_mesh_input_exits_2_with_a_message(tmp_path, capsys):
    spec = json.load(open(EX_SPEC))

    def spec_file(s, name='s.json'):
        p = tmp_path / name
        p.write_text(json.dumps(s))
        return str(p)

    err = _bad(tmp_path, capsys, ['--mesh', str(tmp_path / 'nope.msh'), '--spec', EX_SPEC])
    assert 'nope.msh' in err and 'not found' in err
    (tmp_path / 'part.xyz').write_text('1 2 3\n')
    err = _bad(tmp_path, capsys, ['--mesh', str(tmp_path / 'part.xyz'), '--spec', EX_SPEC])
    assert 'cannot read mesh' in err and 'part.xyz' in err
    err = _bad(tmp_path, capsys, ['--mesh', EX_MESH])
    assert 'needs --spec' in err
    err = _bad(tmp_path, capsys, ['--mesh', EX_MESH, '--spec', str(tmp_path / 'none.json')])
    assert 'spec file' in err and 'not found' in err
    (tmp_path / 'broken.json').write_text('{"units": "mm",')
    assert 'not valid JSON' in _bad(tmp_path, capsys, ['--mesh', EX_MESH, '--spec', str(tmp_path / 'broken.json')])

    s = copy.deepcopy(spec)
    s['regions'][0]['cells'] = {'physical': 'soft_layer'}
    err = _bad(tmp_path, capsys, ['--mesh', EX_MESH, '--spec', spec_file(s)])
    assert "region 'finger'" in err and "'soft_layer'" in err and 'base' in err  # lists the names it has
    s = copy.deepcopy(spec)
    s['regions'][0]['cells'] = {'physical': 7}
    err = _bad(tmp_path, capsys, ['--mesh', EX_MESH, '--spec', spec_file(s)])
    assert 'physical tag 7' in err and 'tags: [1]' in err
    s = copy.deepcopy(spec)
    del s['fixed']
    assert 'no fixed vertices' in _bad(tmp_path, capsys, ['--mesh', EX_MESH, '--spec', spec_file(s)])
    s['fixed'] = [{'box': [[200, 0, 0], [300, 1, 1]]}]
    err = _bad(tmp_path, capsys, ['--mesh', EX_MESH, '--spec', spec_file(s)])
    assert 'fixed #0' in err and 'no fixed vertices' in err
    s = copy.deepcopy(spec)
    s['markers'] = {'tip': {'point': [500, 0, 0]}}
    assert "marker 'tip'" in _bad(tmp_path, capsys, ['--mesh', EX_MESH, '--spec', spec_file(s)])
    s = copy.deepcopy(spec)
    s['actuators'][0]['type'] = 'hydraulic'
    assert "unknown type 'hydraulic'" in _bad(tmp_path, capsys, ['--mesh', EX_MESH, '--spec', spec_file(s)])
    s = copy.deepcopy(spec)
    s['actuators'].append({'name': 'chamber', 'type': 'pneumatic', 'cells': {'physical': 'finger'}})
    s['actuators'][-1]['cells'] = {'elements': [0, 1, 2]}
    err = _bad(tmp_path, capsys, ['--mesh', EX_MESH, '--spec', spec_file(s)])
    assert "region 'finger': 3 cells are already in actuator 'chamber'" in err
    s = copy.deepcopy(spec)
    s['units'] = 'furlong'
    assert "unknown units 'furlong'" in _bad(tmp_path, capsys, ['--mesh', EX_MESH, '--spec', spec_file(s)])
    # a wrong-length actuation vector names the user mesh's actuators
    err = _bad(tmp_path, capsys, ['--mesh', EX_MESH, '--spec', EX_SPEC, '--actuation', '0.9'])
    assert 'needs 3 values' in err and 'cable_2' in err
    # IK for a marker the spec does not define
    rc = main(['ik', '--mesh', EX_MESH, '--spec', EX_SPEC, '--target-mm', '100', '50', '12.5', '--marker', 'nail',
               '--out', str(tmp_path / 'ik')])
    err = capsys.readouterr().err
    assert rc == 2 and "no marker 'nail'" in err and 'tip' in err
