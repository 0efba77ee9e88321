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
