"""The main job's closed loop, short: sim_node + planner_node + recorder as real processes."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.system

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def small_library(tmp_path_factory):
    from frog_sim.core.motion_library import LibrarySpec, generate_library
    path = tmp_path_factory.mktemp("lib") / "small.npz"
    return generate_library(LibrarySpec(n_states=40, horizon=1.5, seed=7), path, workers=2,
                            chunk_size=10, progress=False)


def test_main_job_follows_a_line_to_the_goal(small_library, tmp_path, ros_domain):
    out = tmp_path / "run"
    r = subprocess.run([sys.executable, str(ROOT / "scripts" / "main_job.py"), "--library",
                        str(small_library), "--path", "line", "--max-time", "60",
                        "--real-time-factor", "2", "--out", str(out)],
                       capture_output=True, text=True, timeout=600, env=ros_domain.env)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["goal_reached"], metrics
    assert metrics["mean_distance_m"] < 0.01 and metrics["max_distance_m"] < 0.03, metrics
    assert 0.01 < metrics["mean_speed_along_path_m_per_s"] < 0.06
    assert metrics["decisions"] >= 5 and sum(metrics["primitives_used"].values()) >= 5
    assert (out / "closed_loop.png").stat().st_size > 10_000
    # every node stopped cleanly (SIGINT, exit 0): the script warns otherwise
    assert "warning:" not in r.stdout
    # the recording is complete and decodes
    mcap = Path(metrics["recording"])
    check = subprocess.run(["frog-log", "check", str(mcap)], capture_output=True, text=True,
                           timeout=120)
    assert check.returncode == 0, check.stdout
