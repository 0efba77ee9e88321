"""softkin-twin end to end: emulator, driver, kinematics node and recorder as processes."""

import json
import math
import subprocess

import numpy as np
import pytest

pytestmark = pytest.mark.system
STEPS_PER_M = 200 * 16 / (2 * math.pi * 0.005)   # the driver's defaults: r = 5 mm, 200 steps x 16


def _run(args, env, timeout):
    return subprocess.run(["softkin-twin", *args], env=env, capture_output=True, text=True, timeout=timeout)


def test_twin_refuses_bad_options(ros_domain, tmp_path):
    r = _run(["--curves", "spiral", "--out", str(tmp_path / "x")], ros_domain.env, 60)
    assert r.returncode == 2 and "unknown curve" in r.stderr


@pytest.mark.slow
def test_twin_follows_L_through_the_whole_chain(ros_domain, tmp_path):
    out = tmp_path / "twin"
    r = _run(["--curves", "L", "--out", str(out), "--quiet", "--domain", str(ros_domain.domain_id)],
             ros_domain.env, 400)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    m = json.loads((out / "metrics.json").read_text())
    assert all(code == 0 for code in m["exit_codes"].values()), m["exit_codes"]
    L = m["curves"]["L"]
    assert L["waypoints"] == 55 and L["setpoints"] == 55 and L["feedback_every_waypoint"]
    assert L["chain_exact"]
    # physical model (cables at rest held): the L's first waypoint lies 0.40 mm outside the workspace
    err = np.array(L["achieved_errors_m"])
    assert np.sum(err <= 2e-4) >= 53 and np.median(err) < 5e-5 and err.max() < 5e-4
    for png in ("fig13_L.png", "errors.png"):
        assert (out / png).stat().st_size > 10000

    # the recording, decoded independently: every setpoint's quantised pulls were reached
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    sp, ends = [], []
    files = sorted((out / "recording").glob("*.mcap"))
    with open(files[0], "rb") as fh:
        for _, ch, _, msg in make_reader(fh, decoder_factories=[DecoderFactory()]).iter_decoded_messages(
                topics=["/finger/tendon_setpoints", "/finger/emulator/move_end"]):
            (sp if ch.topic == "/finger/tendon_setpoints" else ends).append(list(msg.position))
    q = np.rint(np.array(sp) * STEPS_PER_M)
    changed = np.concatenate([[True], np.any(q[1:] != q[:-1], axis=1)])
    assert len(sp) == 55 and len(ends) == int(changed.sum())
    assert np.allclose(np.rint(np.array(ends) * STEPS_PER_M), q[changed], atol=1e-6)
    assert m["recording_message_counts"]["/finger/tendon_setpoints"] == 55


def test_real_board_preflight(ros_domain, launch, serial_pair, tmp_path):
    """softkin-twin --port checks the board before anything moves: an emulated board passes, a silent port fails."""
    import time
    link = tmp_path / "marlin_pty"
    launch("marlin_emulator", params={"port_link": str(link)}).wait_for_log("emulated Marlin board", 60)
    deadline = time.monotonic() + 30
    while not link.exists() and time.monotonic() < deadline:
        time.sleep(0.1)
    r = _run(["--port", str(link), "--preflight-only"], ros_domain.env, 60)
    assert r.returncode == 0, r.stdout + r.stderr
    for name in ("handshake", "position", "limits", "zero"):
        assert f"pre-flight {name}" in r.stdout and "FAIL" not in r.stdout, r.stdout
    assert "Marlin 2.1.2" in r.stdout
    _, silent = serial_pair
    r = _run(["--port", silent, "--preflight-only"], ros_domain.env, 60)
    assert r.returncode == 2 and "did not answer M115 with ok" in r.stderr, r.stdout + r.stderr
    assert "nothing was moved" in r.stderr
