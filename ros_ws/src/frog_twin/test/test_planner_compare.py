"""frog-twin --planner-compare's table and planner settings, on made-up results (no ROS)."""

import json
import re

import numpy as np
import pytest

from frog_planner.core.settings import PlannerSettings
from frog_twin.planner_compare import compare_table, planner_settings


def _result(path, planner, seed, mean, finished=True, sim=0, fallbacks=0, floor=0.001):
    return {"path": path, "planner": planner, "seed": seed, "mean_distance_m": mean, "finished": finished,
            "simulator_decisions": sim, "fallbacks": fallbacks, "floor_m": floor}


def test_table_sums_the_seed_means_and_judges_the_targets():
    rng = np.random.default_rng(3)
    means = {(p, k): rng.uniform(0.005, 0.05, 2) for p in ("line", "sine") for k in ("paper", "project", "sim-d1")}
    means["sine", "sim-d1"][:] = means["sine", "paper"] + 0.01          # worse than the paper on the sine
    results = [_result(p, k, s + 1, float(v[s]), sim=5 if k == "sim-d1" else 0, fallbacks=1 if k == "sim-d1" else 0)
               for (p, k), v in means.items() for s in range(2)]
    text = compare_table(results)
    sums = {k: sum(means[p, k].mean() for p in ("line", "sine")) for k in ("paper", "project", "sim-d1")}
    row = next(line for line in text.splitlines() if line.startswith("| **sum**"))
    got = [float(x) for x in re.findall(r"\*\*([\d.]+)\*\*", row)]
    assert got == pytest.approx([sums[k] * 100 for k in ("paper", "project", "sim-d1")], abs=0.006)
    best = min(("project", "sim-d1"), key=sums.get)
    ratio = sums[best] / sums["paper"]
    assert f"Best mode {best}" in text and f"{ratio:.2f} x the paper" in text
    assert ("met" if ratio <= 0.7 else "NOT met") in text
    worse = [p for p in ("line", "sine") if means[p, best].mean() > means[p, "paper"].mean()]
    listed = re.search(r"worse than the paper planner: (.*)\.", text).group(1)
    assert [w.split(" (")[0] for w in listed.split(", ")] == (worse or ["none"])
    assert "sim-d1 20 / 4" in text           # 2 paths x 2 seeds x (5 decisions, 1 fallback)
    assert "Decisions made within the period: 83.3 % (target >= 99 %: NOT met)" in text
    worse_sim = [p for p in ("line", "sine") if means[p, "sim-d1"].mean() > means[p, "project"].mean()]
    listed = re.search(r"against the library mode \(project\): worse on (.*) \(target", text).group(1)
    assert [w.split(" (")[0] for w in listed.split(", ")] == (worse_sim or ["no path"])
    assert "(2/2)" in text


def test_worse_paths_carry_the_difference_and_its_standard_error():
    # sim-d1 worse than the project on the sine by 0.2 cm; seeds spread: project 1, 2, 3 mm; sim-d1 2, 4, 6 mm
    results = [_result("sine", "project", s, v) for s, v in ((1, 0.001), (2, 0.002), (3, 0.003))]
    results += [_result("sine", "sim-d1", s, v, sim=5) for s, v in ((1, 0.002), (2, 0.004), (3, 0.006))]
    # sample variances 1e-6 and 4e-6 m^2 over 3 seeds each: s.e. sqrt(5e-6 / 3) = 1.29 mm
    assert "worse on sine (+0.20 +- 0.13 cm)" in compare_table(results)
    one_seed = compare_table([r for r in results if r["seed"] == 1])
    assert "worse on sine (+0.10 cm)" in one_seed and "standard error" not in one_seed


def test_a_stopped_comparison_sums_only_the_paths_every_planner_has_run():
    # stopped during sin1: the paper planner has one seed there, the others none
    results = [_result(p, k, s, v) for p, k, s, v in (
        ("line", "paper", 1, 0.004), ("line", "project", 1, 0.002), ("sine", "paper", 1, 0.010),
        ("sine", "project", 1, 0.008), ("sin1", "paper", 1, 0.025))]
    text = compare_table(results)
    row = next(line for line in text.splitlines() if line.startswith("| **sum"))
    assert "2 paths" in row and re.findall(r"\*\*([\d.]+)\*\*", row) == ["1.40", "1.00"]
    assert "nan" not in text.split("| sin1 |")[0] + text.split("| **sum")[1]
    assert "= 0.71 x the paper planner's 1.40 cm (target <= 0.70: NOT met); paths worse than the paper planner: none" \
        in text
    first = compare_table(results[:2] + [_result("line", "paper", 2, 0.005)])    # stopped in the first path
    assert "sum of the 0 paths" in first and "Best mode" not in first


def test_floor_is_the_lowest_of_the_planners_models():
    # the project's model turns less tightly (higher floor) than the paper's; the project ran first
    results = [_result("sine", "project", 1, 0.008, floor=0.0062), _result("sine", "paper", 1, 0.010, floor=0.0035),
               _result("line", "project", 1, 0.003, floor=float("nan")), _result("line", "paper", 1, 0.005, floor=0.0)]
    rows = {line.split("|")[1].strip(): line.split("|")[2].strip() for line in compare_table(results).splitlines()
            if line.startswith("| ") and not line.startswith("| path")}
    assert rows["sine"] == "0.35" and rows["line"] == "0.00"


def test_compared_planners_share_the_period_and_differ_as_specified():
    base = PlannerSettings(depth=1)
    paper, t = planner_settings("paper", base, 1.43)
    assert t == "library" and paper.period == 1.43 and paper.metric == "relative" and paper.heading_lookahead == 0
    project, t = planner_settings("project", base, 1.43)
    assert t == "library" and project.heading_lookahead == base.heading_lookahead and project.period == 1.43
    for kind, depth in (("sim-d1", 1), ("sim-d2", 2)):
        s, t = planner_settings(kind, base, 1.43)
        assert t == "simulator" and s.depth == depth and s.w_distance == base.w_distance
    sim_paper, t = planner_settings("sim-paper", base, 1.43)
    assert t == "simulator" and sim_paper == paper        # the paper's cost, only the predictions differ


# --- resuming an interrupted comparison (frog-twin --planner-compare, runs faked: no ROS) ---

def _fake_twin(monkeypatch, calls, stop_at=None):
    """run_twin replaced: a run's numbers and track follow from its label alone."""
    import zlib
    from types import SimpleNamespace

    import frog_twin.twin as twin

    def run_twin(args, label, out, path_settings, start, settings, duration):
        calls.append(label)
        if len(calls) == stop_at:
            raise KeyboardInterrupt("SIGTERM")           # the twin's stop-signal handler
        r = np.random.default_rng(zlib.crc32(label.encode()))
        t = np.arange(0.0, 5.0, 0.5)
        truth = np.column_stack([t, r.normal(size=len(t)), r.normal(size=len(t))])
        rec = SimpleNamespace(truth=truth, path=np.column_stack([np.linspace(0, 1, 5), np.zeros(5)]))
        m = {"mean_distance_m": float(r.uniform(0.002, 0.02)), "max_distance_m": 0.03, "goal_reached": True,
             "completion_time_s": 4.0, "wall_time_s": 1.0, "primitives_used": {"C": 3}, "plot": label + ".png",
             "start_time_s": 1.0, "feasibility": {"floor_mean_distance_m": 0.001}}
        return rec, m
    monkeypatch.setattr(twin, "run_twin", run_twin)


def _compare(tmp_path, out, *extra):
    import frog_twin.twin as twin
    lib = tmp_path / "lib.npz"
    lib.touch()
    return twin.main(["--planner-compare", "--compare-paths", "line,sine", "--compare-planners", "paper,project",
                      "--library", str(lib), "--out", str(out), *extra])


def test_a_stopped_comparison_resumes_to_the_same_table(tmp_path, monkeypatch, capsys):
    whole = []
    _fake_twin(monkeypatch, whole)
    assert _compare(tmp_path, tmp_path / "whole") == 0
    assert len(whole) == 4
    calls = []
    _fake_twin(monkeypatch, calls, stop_at=3)
    assert _compare(tmp_path, tmp_path / "part") == 130
    assert "2 of 4 runs done: the same command with --out" in (tmp_path / "part" / "compare.md").read_text()
    assert (tmp_path / "part" / "line_compare.png").is_file() and not (tmp_path / "part" / "sine_compare.png").exists()
    capsys.readouterr()
    calls.clear()
    _fake_twin(monkeypatch, calls)
    assert _compare(tmp_path, tmp_path / "part") == 0
    assert calls == whole[2:]                         # only what was missing
    assert "2 of 4 runs done earlier" in capsys.readouterr().out
    part, full = ((tmp_path / d / "compare.md").read_text() for d in ("part", "whole"))
    assert part.split("\n", 1)[1] == full.split("\n", 1)[1] and "runs done" not in part
    assert json.loads((tmp_path / "part" / "compare.json").read_text()) == \
        json.loads((tmp_path / "whole" / "compare.json").read_text())
    assert (tmp_path / "part" / "sine_compare.png").is_file()


def test_a_resume_with_other_settings_is_refused_before_any_run(tmp_path, monkeypatch, capsys):
    calls = []
    _fake_twin(monkeypatch, calls, stop_at=3)
    assert _compare(tmp_path, tmp_path / "c") == 130          # line_paper_s1 and line_project_s1 done
    calls.clear()
    _fake_twin(monkeypatch, calls)
    assert _compare(tmp_path, tmp_path / "c", "--real-time-factor", "0.5") == 2
    assert calls == []
    err = capsys.readouterr().err
    assert "line_paper_s1" in err and "other settings (real_time_factor)" in err and "another --out" in err
    assert _compare(tmp_path, tmp_path / "c", "--w-distance", "7000") == 2      # the project planner's cost
    err = capsys.readouterr().err
    assert "line_project_s1" in err and "other settings (settings)" in err and calls == []


def test_a_damaged_result_is_run_again(tmp_path, monkeypatch):
    calls = []
    _fake_twin(monkeypatch, calls)
    assert _compare(tmp_path, tmp_path / "c") == 0
    (tmp_path / "c" / "sine" / "sine_paper_s1" / "compare_result.json").write_text('{"path": "si')
    calls.clear()
    assert _compare(tmp_path, tmp_path / "c") == 0
    assert calls == ["sine_paper_s1"]
