"""The ``softkin`` command line: JSON + PNG output, clear errors with a non-zero exit."""
import json

import numpy as np

from softkin_fk.cli import main


def test_fk_writes_json_and_png(tmp_path, capsys):
    out = tmp_path / 'fk'
    rc = main(['fk', '--resolution', '1', '--pull-mm', '1', '1', '2', '--out', str(out), '--quiet'])
    assert rc == 0
    data = json.loads((out / 'result.json').read_text())
    assert data['converged'] and data['units'] == 'm'
    tip = np.array(data['markers']['tip'])
    assert tip[1] > 0.025  # bent towards the cables (+y)
    assert (out / 'deformed.png').stat().st_size > 1000
    assert json.loads(capsys.readouterr().out)['converged']


def test_bad_input_gives_error_and_exit_2(tmp_path, capsys):
    rc = main(['fk', '--resolution', '1', '--actuation', '0.5', '1', '1', '--out', str(tmp_path)])
    err = capsys.readouterr().err
    assert rc == 2 and 'outside its bounds' in err and '0.5' in err
    rc = main(['fk', '--resolution', '1', '--pull-mm', '1', '--out', str(tmp_path)])
    assert rc == 2 and 'needs 3 values' in capsys.readouterr().err
    rc = main(['trajectory', '--resolution', '1', '--csv', str(tmp_path / 'nope.csv'), '--out', str(tmp_path)])
    assert rc == 2 and 'not found' in capsys.readouterr().err
    rc = main(['calibrate', '--ratios', '0.7', '--out', str(tmp_path)])
    assert rc == 2 and 'must exceed 1' in capsys.readouterr().err


def test_help_shows_user_mesh_examples(capsys):
    for argv in (['--help'], ['fk', '--help']):
        try:
            main(argv)
        except SystemExit as exc:
            assert exc.code == 0
        out = capsys.readouterr().out
        assert '--mesh part.msh --spec part.json --actuation 0.9' in out


def test_fk_mesh_out_writes_a_gmsh_file_meshio_reads(tmp_path):
    import meshio
    path = tmp_path / 'deformed.msh'
    rc = main(['fk', '--resolution', '1', '--pull-mm', '1', '1', '2', '--out', str(tmp_path), '--quiet',
               '--mesh-out', str(path)])
    assert rc == 0
    m = meshio.read(str(path))
    assert sorted({c.type for c in m.cells}) == ['tetra', 'triangle'] and len(m.points) == 450


def test_ik_jacobians_agree_through_the_cli(tmp_path, capsys):
    """`softkin ik --jacobian implicit|central`: both reach a target inside the workspace
    within lambda, and land on the same actuation to IK tolerance (the implicit sensitivity
    is the same gradient as central differences)."""
    results = {}
    for jac in ('central', 'implicit'):
        out = tmp_path / jac
        rc = main(['ik', '--resolution', '1', '--target-mm', '100', '54', '12.5', '--jacobian', jac,
                   '--out', str(out), '--quiet'])
        assert rc == 0
        capsys.readouterr()
        results[jac] = json.loads(next(out.rglob('result.json')).read_text())
    for r in results.values():
        assert r['success'] and r['error_m'] <= 0.2e-3
    reached = [np.asarray(results[j]['reached']) for j in ('central', 'implicit')]
    assert np.linalg.norm(reached[0] - reached[1]) < 0.4e-3
