"""Hardware replay, short and simulator-only: ``frog-twin --replay RUN.csv --path P.csv --no-vision --direct``.

Real processes (sim_node with its primitive executor, planner_node, recorder) replay the
authors' sin1 run for a few simulated seconds; the checks read the written table, JSON,
plot and recording. Skips, naming the file, without the measured data.
"""

import csv
import json
import math
import shutil
import subprocess
from pathlib import Path

import pytest

pytestmark = [pytest.mark.system, pytest.mark.usefixtures("one_twin")]


@pytest.fixture(scope="module")
def sin1_run():
    from frog_sim.core.actuation import find_data_file
    try:
        return find_data_file("hardware_runs/sin1.csv")
    except FileNotFoundError as exc:
        pytest.skip(f"measured data not available: {exc}")


def test_short_replay_writes_the_comparison(sin1_run, library, tmp_path):
    from frog_twin.core.replay import real_metrics, replay_setup
    from frog_twin.core.twin_recording import read_twin_recording
    runs = tmp_path / "runs"
    runs.mkdir()
    shutil.copy(sin1_run, runs / "sin1.csv")
    path_file = runs / "reference.csv"             # not the default name: --path is what is read
    shutil.copy(sin1_run.with_name("sin1_path.csv"), path_file)
    out = tmp_path / "replay"
    r = subprocess.run(["frog-twin", "--replay", str(runs / "sin1.csv"), "--path", str(path_file), "--no-vision",
                        "--direct", "--duration", "6", "--seeds", "1", "--library", str(library), "--out", str(out)],
                       capture_output=True, text=True, timeout=240)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    folder = out / "sin1"
    for name in ("sin1_replay.png", "sin1_replay.json", "sin1_replay.csv", "sin1_replay.txt", "sin1.png"):
        assert (folder / name).stat().st_size > 100, name
    assert (folder / "sin1_replay.png").stat().st_size > 20_000
    with open(folder / "sin1_replay.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert [row["who"] for row in rows] == ["real", "twin s1"]
    assert set(rows[0]) >= {"mean_distance_cm", "max_distance_cm", "signed_lateral_cm", "time_s",
                            "mean_speed_cm_per_s", "primitives"}
    printed = [line.split()[:2] for line in r.stdout.splitlines() if line.startswith("sin1 ")]
    assert printed == [["sin1", "real"], ["sin1", "twin"]], r.stdout[-2000:]
    res = json.loads((folder / "sin1_replay.json").read_text())
    # the real row is the real robot's log, scored by the core (the same numbers)
    setup = replay_setup(runs / "sin1.csv", path_file)
    real = real_metrics(setup)
    assert res["real"]["mean_distance_m"] == pytest.approx(real["mean_distance_m"], rel=1e-9)
    assert res["real"]["decisions"] >= 10 and res["real"]["finished"]
    # the twin ran the fitted period from the logged start pose along the run's waypoints
    assert res["planner"]["period"] == pytest.approx(setup.period) and 1.40 < setup.period < 1.45
    assert res["planner_kind"] == "project"
    # without the serial link sim_node fires each primitive the robot's delay after its stamp (simulated
    # time); the run ends at a 10 cm finish line, as it is scored
    assert res["robot_loop_params"]["sim_node"]["command_delay_s"] == pytest.approx(0.10)
    assert res["settings"]["finish_line_m"] == pytest.approx(0.10)
    assert res["spread"]["mean_distance_m"]["n"] == 1 and res["spread"]["mean_distance_m"]["of"] == 2
    (twin,) = res["twins"]
    rec = read_twin_recording([Path(f) for f in twin["recording"]], with_images=False)
    x0, y0, h0 = setup.start_pose
    first = rec.truth[0]
    assert math.hypot(first[1] - x0, first[2] - y0) < 1e-3
    assert abs((first[3] - h0 + math.pi) % (2 * math.pi) - math.pi) < 1e-3
    assert rec.path[0] == pytest.approx(setup.path[0], abs=1e-9) and len(rec.path) == len(setup.path)
    # the planner saw the heading of the tag as the robot's was mounted (turned by -tag offset), the
    # position and the world as they are
    tag_yaw = res["settings"]["tag_yaw_rad"]
    assert tag_yaw == pytest.approx(-setup.tag_offset) and abs(tag_yaw) > math.radians(2)
    truth = {round(t, 4): (x, y, h) for t, x, y, h in rec.truth}
    pairs = [(truth[round(t, 4)], (x, y, h)) for t, x, y, h in rec.tracked if round(t, 4) in truth]
    assert len(pairs) > 100
    for (x, y, h), (xs, ys, hs) in pairs:
        assert (xs, ys) == (x, y)
        assert math.remainder(hs - h - tag_yaw, 2 * math.pi) == pytest.approx(0.0, abs=1e-6)
    # it moved and decided: a few periods in 6 simulated seconds, at most one a period (the report ends
    # at the time limit, not when the nodes had stopped: the world runs on meanwhile)
    most = int(6 / setup.period) + 1
    assert 3 <= twin["decisions"] <= most and twin["mean_distance_m"] < 0.1, (twin["decisions"], most)
    assert twin["duration_s"] <= 6.0 + 1e-6, twin["duration_s"]      # scored to the run's end, no further
    # the same replay again into the same folder: the recorder keeps the first file and starts the next;
    # the new report reads only its own (it had read both: every decision twice, two trajectories)
    r = subprocess.run(["frog-twin", "--replay", str(runs / "sin1.csv"), "--path", str(path_file), "--no-vision",
                        "--direct", "--duration", "6", "--seeds", "1", "--library", str(library), "--out", str(out)],
                       capture_output=True, text=True, timeout=240)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    assert "1 earlier recording(s)" in r.stdout, r.stdout[-2000:]
    (again,) = json.loads((folder / "sin1_replay.json").read_text())["twins"]
    assert [Path(f).name for f in again["recording"]] == ["sin1_001.mcap"]
    assert 3 <= again["decisions"] <= most, (again["decisions"], most)     # both files read: about twice
    assert again["duration_s"] <= 6.0 + 1e-6, again["duration_s"]


@pytest.mark.parametrize("args, named", [
    (["--path", "line", "--aligned-tag"], "--aligned-tag"),
    (["--path", "line", "--ideal-loop"], "--ideal-loop"),
    (["--replay-all", ".", "--ideal-loop"], "--ideal-loop goes with --paper-cost"),
    (["--path", "line", "--yaw-disturbance-sd", "-1"], "--yaw-disturbance-sd"),
    (["--path", "line", "--yaw-disturbance-tau", "0"], "--yaw-disturbance-tau"),
])
def test_bad_replay_and_twin_variability_options_exit_2(args, named):
    r = subprocess.run(["frog-twin", *args], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and named in r.stderr, r.stderr[-2000:]
