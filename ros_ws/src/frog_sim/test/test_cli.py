"""frog-sim command line: outputs, metadata and errors on bad input."""
import json

import numpy as np

from frog_sim.cli import main


def test_gait_run_writes_csv_npz_metadata_and_png(tmp_path, capsys):
    out = tmp_path / 'gait'
    assert main(['gait', '--frequency', '1.0', '--duration', '0.5', '--quiet', '--out', str(out)]) == 0
    for name in ('trajectory.csv', 'trajectory.npz', 'metadata.json', 'trajectory.png'):
        assert (out / name).stat().st_size > 0, name
    meta = json.loads((out / 'metadata.json').read_text())
    assert meta['units']['positions'] == 'm' and meta['params']['egain_vol_pct'] == 10.0
    assert meta['gait']['frequency_hz'] == 1.0 and 'code_version' in meta
    data = np.load(out / 'trajectory.npz')
    assert data['positions'].shape[1:] == (128, 2)
    csv = np.loadtxt(out / 'trajectory.csv', delimiter=',', skiprows=3)
    assert csv.shape[1] == 9 and abs(csv[-1, 0] - 0.5) < 1e-9


def test_primitives_with_initial_velocity(tmp_path):
    out = tmp_path / 'prims'
    assert main(['primitives', '--sequence', 'B,3', '--period', '0.3', '--forward', '0.02',
                 '--quiet', '--no-plot', '--out', str(out)]) == 0
    data = np.load(out / 'trajectory.npz')
    assert data['body_velocity'][0, 0] > 0.019


def test_bad_input_exits_nonzero_with_the_value_named(tmp_path, capsys):
    assert main(['primitives', '--sequence', 'A,Z', '--quiet', '--out', str(tmp_path / 'x')]) == 2
    assert "'Z'" in capsys.readouterr().err
    assert main(['gait', '--frequency', '2.5', '--quiet', '--out', str(tmp_path / 'y')]) == 2
    assert '2.5 Hz' in capsys.readouterr().err
    assert main(['gait', '--egain', '60', '--quiet', '--out', str(tmp_path / 'z')]) == 2
    assert 'EGaIn 60' in capsys.readouterr().err      # unmeasured designs inside the hull are interpolated
    assert main(['gait', '--phase', '1.5', '--quiet']) == 2
    assert main([]) == 2
    # frog-sim disturbance: its grids and draws are checked before any data is read
    assert main(['disturbance', '--taus', '1,x', '--quiet']) == 2
    assert "--taus '1,x'" in capsys.readouterr().err
    assert main(['disturbance', '--kicks', '0.7', '--quiet']) == 2
    assert '[0, 0.5]' in capsys.readouterr().err
    assert main(['disturbance', '--seeds', '0', '--quiet']) == 2
    assert '--seeds 0' in capsys.readouterr().err
