"""Hardware replay set-up and scoring (frog_twin.core.replay) on a synthetic log with known answers.

The test writes a log in the authors' format (two header lines, a start-up burst of rows
1 ms apart, then ~70 ms frames with jitter, the last action as a letter) of a robot gliding
straight at 2 cm/s with heading h0 while its tag reads theta = h0 - offset, with decisions
every P alternating B and A; and the reference path 2 cm to the robot's right (so the robot
is 2 cm to the left of it).
"""

import csv
import math

import numpy as np
import pytest

from frog_twin.core import replay

H0 = math.radians(-110.0)          # body heading (radians, world frame)
OFFSET = math.radians(-7.0)        # body heading - tag theta
PERIOD = 1.3                       # decision period [s]
SPEED = 0.02                       # [m/s]
FIRST_DECISION = 1.0               # log time of the first decision after the burst [s]
P0 = np.array([0.05, 0.15])        # position at log time 0 (after the burst) [m]


def _pose_at(t):
    d = np.array([math.cos(H0), math.sin(H0)])
    return P0 + SPEED * np.asarray(t)[..., None] * d


def write_synthetic_run(folder, name="synth", decisions=12, seed=3, path_side=-0.02, offset=OFFSET):
    rng = np.random.default_rng(seed)
    dec = FIRST_DECISION + PERIOD * np.arange(decisions)
    prims = ["B" if k % 2 == 0 else "A" for k in range(decisions)]
    frames = [0.0]
    while frames[-1] < dec[-1] + PERIOD:
        frames.append(frames[-1] + 0.07 + rng.uniform(-0.015, 0.015))
    frames = np.array(frames)
    xy = _pose_at(frames)
    theta = np.mod(H0 - offset, 2 * np.pi)
    act = np.array(["I"] * len(frames))
    for k, d in enumerate(dec):
        act[frames >= d] = prims[k]
    base = 61_000_000.0
    with open(folder / f"{name}.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["CV Data Logger started on:", "2022-2-24_172209"])
        w.writerow(["Timestamp (millisec since midnight today)", "x", "y", "theta", "xdot", "ydot", "thetadot",
                    "cost", "last action"])
        for i in range(50):   # the tracker's queue draining
            w.writerow([f"{base - 120 + i:.0f}", xy[0, 0], xy[0, 1], theta, 0, 0, 0, 300.0, 0, 0, 300.0, "I"])
        for i, t in enumerate(frames):
            w.writerow([f"{base + 1000 * t:.0f}", xy[i, 0], xy[i, 1], theta, 0, 0, 0, 300.0, 0, 0, 300.0, act[i]])
    # the reference path: the robot's straight line shifted by path_side to its left (negative = right)
    left = np.array([-math.sin(H0), math.cos(H0)])
    s = np.linspace(-0.01, SPEED * (dec[-1] + PERIOD) + 0.05, 100)
    path = P0 + s[:, None] * np.array([math.cos(H0), math.sin(H0)]) + path_side * left
    with open(folder / f"{name}_path.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        for x, y in path:
            w.writerow([f"{x:.18e}", f"{y:.18e}", f"{H0:.18e}", "0.0"])
    return dec, prims, path


@pytest.fixture
def synthetic_run(tmp_path):
    dec, prims, path = write_synthetic_run(tmp_path)
    return tmp_path, dec, prims, path


def test_setup_reads_start_pose_period_tag_offset_and_waypoints(synthetic_run):
    folder, dec, prims, path = synthetic_run
    s = replay.replay_setup(folder / "synth.csv")          # path file found beside the log
    assert s.path_file == folder / "synth_path.csv"
    assert s.period == pytest.approx(PERIOD, abs=0.005)
    # the tag offset is estimated on the run's own B decisions (no line runs in the folder)
    assert s.tag_offset == pytest.approx(OFFSET, abs=math.radians(0.2)), s.tag_offset_source
    assert "synth" in s.tag_offset_source
    # start pose: the body pose at the first decision (position within 1.5 mm: frame timing)
    x, y, h = s.start_pose
    assert np.hypot(*(np.array([x, y]) - _pose_at(dec[0]))) < 0.0015
    assert h == pytest.approx(H0, abs=1e-6)
    assert -math.pi <= h < math.pi
    # the body heading of every frame has the offset applied
    assert np.allclose(s.pose[:, 2], H0 + 2 * np.pi * np.round((s.pose[:, 2] - H0) / (2 * np.pi)), atol=1e-6)
    # decisions and their primitives, from the first decision on
    assert s.primitives[:len(prims)] == prims[:len(s.primitives)]
    assert len(s.primitives) >= len(prims) - 1
    assert 0.0 <= s.time[0] < 0.1 and s.decision_times[0] == pytest.approx(0.0, abs=1e-9)   # first frame, decision
    np.testing.assert_allclose(s.path, path, atol=1e-12)


def test_a_given_tag_offset_wins_and_line_runs_are_preferred(tmp_path):
    write_synthetic_run(tmp_path, name="sinx")
    s = replay.replay_setup(tmp_path / "sinx.csv", tag_offset=0.1)
    assert s.tag_offset == 0.1 and s.tag_offset_source == "given"
    wrapped = (H0 - OFFSET + 0.1 + math.pi) % (2 * math.pi) - math.pi      # theta + the given offset
    assert s.start_pose[2] == pytest.approx(wrapped, abs=1e-6)
    # a straight-line run beside it (other offset) is what the tag offset is estimated on
    import shutil
    sub = tmp_path / "with_line"
    sub.mkdir()
    shutil.copy(tmp_path / "sinx.csv", sub / "sinx.csv")
    shutil.copy(tmp_path / "sinx_path.csv", sub / "sinx_path.csv")
    write_synthetic_run(sub, name="line7", offset=math.radians(-3.0))
    s = replay.replay_setup(sub / "sinx.csv")
    assert s.tag_offset == pytest.approx(math.radians(-3.0), abs=math.radians(0.2))
    assert "line7" in s.tag_offset_source


def test_waypoints_reach_the_planner_unchanged(synthetic_run, tmp_path):
    from frog_planner.core.settings import PathSettings
    folder, _, _, path = synthetic_run
    s = replay.replay_setup(folder / "synth.csv", folder / "synth_path.csv")
    wp = replay.write_waypoints(s.path, tmp_path / "wp.csv")
    built = PathSettings(path_type="waypoints", waypoint_file=str(wp)).build()
    np.testing.assert_allclose(built.points, path, atol=1e-9)


def test_real_metrics_of_the_synthetic_run(synthetic_run):
    """The robot glides 2 cm left of the path at 2 cm/s: mean = max = 2 cm, signed +2 cm, 2 cm/s."""
    folder, dec, prims, _ = synthetic_run
    s = replay.replay_setup(folder / "synth.csv")
    m = replay.real_metrics(s)
    assert m["mean_distance_m"] == pytest.approx(0.02, abs=2e-4)
    assert m["max_distance_m"] == pytest.approx(0.02, abs=2e-4)
    assert m["mean_signed_lateral_m"] == pytest.approx(0.02, abs=2e-4)
    assert not m["finished"]                     # the path runs 5 cm past the log's end
    assert m["mean_speed_along_path_m_per_s"] == pytest.approx(SPEED, rel=0.02)
    assert m["primitives_used"] == {"A": prims[:m["decisions"]].count("A"), "B": prims[:m["decisions"]].count("B")}
    # on the other side of the path the sign flips, nothing else changes
    other = folder / "right"
    other.mkdir()
    write_synthetic_run(other, path_side=+0.02)
    m2 = replay.real_metrics(replay.replay_setup(other / "synth.csv", tag_offset=s.tag_offset))
    assert m2["mean_signed_lateral_m"] == pytest.approx(-0.02, abs=2e-4)
    assert m2["mean_distance_m"] == pytest.approx(m["mean_distance_m"], abs=1e-9)


def test_find_runs_needs_a_path_file(synthetic_run):
    folder = synthetic_run[0]
    (folder / "orphan.csv").write_text("no path file beside it\n")
    assert [r.name for r, _ in replay.find_runs(folder)] == ["synth.csv"]


def test_missing_files_are_named(tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.csv"):
        replay.replay_setup(tmp_path / "nope.csv")
    write_synthetic_run(tmp_path)
    with pytest.raises(FileNotFoundError, match="other_path.csv"):
        replay.replay_setup(tmp_path / "synth.csv", tmp_path / "other_path.csv")


def _m(d, lat):
    return {"mean_distance_m": d, "mean_signed_lateral_m": lat, "max_distance_m": 2 * d, "completion_time_s": 20.0,
            "finished": True, "mean_speed_along_path_m_per_s": 0.02, "primitives_used": {"B": 3}, "decisions": 3}


def test_pooled_ratios_over_runs_and_seeds():
    results = [
        {"run": "a", "real": _m(0.02, 0.02), "twins": [_m(0.008, 0.008), _m(0.012, 0.012)]},
        {"run": "b", "real": _m(0.04, -0.03), "twins": [_m(0.02, -0.015)]},
        {"run": "c", "real": _m(0.01, 0.005), "twins": [_m(0.03, -0.02)]},      # robot < 1 cm off: not in lateral
    ]
    p = replay.pooled(results)
    assert p["mean_distance_ratio_twin_over_real"] == pytest.approx(0.06 / 0.07)
    assert p["lateral_runs"] == ["a", "b"]
    assert p["signed_lateral_ratio_twin_over_real"] == pytest.approx((0.01 + 0.015) / (0.02 + 0.03))
    assert p["signed_lateral_ratio_se"] is None          # run b has one seed: no spread known
    assert p["mean_distance_ratio_se"] is None
    results[1]["twins"].append(_m(0.02, -0.025))
    # a: seeds 0.008, 0.012 -> s^2 = 8e-6, /2; b: -0.015, -0.025 -> s^2 = 5e-5, /2
    assert replay.pooled(results)["signed_lateral_ratio_se"] == pytest.approx(math.sqrt(4e-6 + 2.5e-5) / 0.05)
    results[2]["twins"].append(_m(0.02, -0.02))
    # distances a: 0.008, 0.012 (s^2 8e-6); b: 0.02, 0.02 (0); c: 0.03, 0.02 (5e-5); real sum 0.07
    assert replay.pooled(results)["mean_distance_ratio_se"] == pytest.approx(math.sqrt(4e-6 + 2.5e-5) / 0.07)
    results[2]["twins"].pop()
    assert "+- 0.11 (se, seed spread)" in replay.format_summary(
        replay.summary_rows([dict(r, setup={"period_s": 1.43}) for r in results]), replay.pooled(results))
    results[1]["twins"].pop()
    # the twin on the other side of the path gives a negative ratio
    results[1]["twins"] = [_m(0.02, +0.03)]
    assert replay.pooled(results)["signed_lateral_ratio_twin_over_real"] == pytest.approx((0.01 - 0.03) / 0.05)
    for r in results:
        r["setup"] = {"period_s": 1.43}
    rows = replay.summary_rows(results)
    text = replay.format_summary(rows, replay.pooled(results))
    assert [line.split()[0] for line in text.splitlines()[2:5]] == ["a", "b", "c"]
    assert text.splitlines()[-3].startswith("pooled all (3 runs)")
    assert replay.pooled_row(rows, replay.pooled(results))["mean_ratio"] == pytest.approx(0.06 / 0.07)


def test_seed_spread_ranks_the_real_run_among_the_seeds():
    sp = replay.seed_spread([0.03, 0.01, 0.05, 0.02, 0.04], 0.035)
    assert (sp["median"], sp["min"], sp["max"]) == (0.03, 0.01, 0.05)
    assert (sp["rank"], sp["of"]) == (4, 6)               # three seeds below 3.5 cm: fourth of six
    assert replay.seed_spread([0.03, 0.01], 0.001)["rank"] == 1
    assert replay.seed_spread([0.03, 0.01], 0.1)["rank"] == 3
    with pytest.raises(ValueError):
        replay.seed_spread([], 1.0)


def _ms(d, lat, v):
    return dict(_m(d, lat), mean_speed_along_path_m_per_s=v)


def test_pooled_speed_and_per_seed_spread():
    """Two runs, three seeds each: the pooled ratios per seed and their spread, by hand."""
    results = [
        {"run": "ellipse1", "real": _ms(0.04, 0.03, 0.020),
         "twins": [_ms(0.02, 0.01, 0.024), _ms(0.04, 0.02, 0.020), _ms(0.06, 0.04, 0.022)]},
        {"run": "sin2", "real": _ms(0.02, -0.02, 0.030),
         "twins": [_ms(0.01, -0.01, 0.030), _ms(0.03, 0.00, 0.036), _ms(0.02, -0.03, 0.027)]},
    ]
    p = replay.pooled(results)
    # speed: seed means 0.022 and 0.031 over real 0.020 + 0.030
    assert p["mean_speed_ratio_twin_over_real"] == pytest.approx(0.053 / 0.050)
    # per seed k: distances (0.02+0.01, 0.04+0.03, 0.06+0.02) / 0.06
    assert p["per_seed"]["mean_distance_ratio"] == pytest.approx([0.5, 7 / 6, 4 / 3])
    # lateral (both runs > 1 cm off): (0.01 + 0.01, 0.02 + 0.00, 0.04 + 0.03) / 0.05
    assert p["per_seed"]["signed_lateral_ratio"] == pytest.approx([0.4, 0.4, 1.4])
    assert p["per_seed"]["mean_speed_ratio"] == pytest.approx([0.054 / 0.05, 0.056 / 0.05, 0.049 / 0.05])
    assert p["spread"]["mean_distance_ratio"]["median"] == pytest.approx(7 / 6)
    assert p["spread"]["mean_distance_ratio"]["rank"] == 2      # 1 lies above one seed's 0.5
    assert p["spread"]["mean_speed_ratio"]["rank"] == 2
    groups = replay.pooled_groups(results)
    assert set(groups) == {"all", "ellipse", "sin"}
    assert groups["ellipse"]["mean_speed_ratio_twin_over_real"] == pytest.approx(0.022 / 0.020)
    for r in results:
        r["setup"] = {"period_s": 1.43}
    rows = replay.summary_rows(results)
    assert rows[0]["speed_ratio"] == pytest.approx(1.1)
    assert (rows[0]["twin_mean_median"], rows[0]["twin_mean_min"], rows[0]["twin_mean_max"]) == \
        pytest.approx((4.0, 2.0, 6.0))
    assert rows[0]["real_mean_rank"] == 2 and rows[1]["real_lateral_rank"] == 2
    assert rows[1]["real_speed_rank"] == 2          # 2.7 below 3.0; the tie at 3.0 does not count as below
    text = replay.format_summary(rows, p, groups)
    assert "pooled ellipse (1 runs)" in text and "pooled sin (1 runs)" in text and "pooled all (2 runs)" in text


def test_a_missing_figure_is_a_dash_of_the_columns_width_and_alignment():
    # a run where a seed did not finish has no twin time: its cell keeps the column's width
    assert replay._fmt(None, 1, "7.1f") == "      -"
    assert replay._fmt(None, 1, "<8.1f") == "-       "
    assert replay._fmt(float("nan"), 1, "^5.1f") == "  -  "
    assert replay._fmt(12.345, 1, "<8.1f") == "12.3    "
