"""``frog-twin --fault-campaign`` shared by shards and resumed from its folder (runs faked, no ROS)."""

import json

import frog_twin.twin as twin


def _fake_runs(monkeypatch, calls, fail_label=None):
    def run_path(args, path, out, faults=()):
        label = out.parent.name
        calls.append(label)
        if label == fail_label:
            raise RuntimeError("the twin broke")
        return {"faults": {"outcome": "completed", "stop_reason": None, "stale_pulses": [], "recorder_lost": 0,
                           "per_fault": [{"fault": f.label(), "recovery_s": 1.5} for f in faults]}}
    monkeypatch.setattr(twin, "run_path", run_path)


def _campaign(tmp_path, *extra):
    lib = tmp_path / "lib.npz"
    lib.touch()
    return twin.main(["--fault-campaign", "--campaign-faults", "occlude@0+4;emergency@0", "--moments", "1",
                      "--seeds", "2", "--campaign-paths", "line", "--library", str(lib),
                      "--out", str(tmp_path / "c"), *extra])


def test_two_shards_share_the_campaign_and_a_rerun_resumes_it(tmp_path, monkeypatch, capsys):
    calls = []
    _fake_runs(monkeypatch, calls)
    assert _campaign(tmp_path, "--campaign-shard", "1/2") == 0
    first = list(calls)
    assert len(first) == 2
    assert "2 of 4 runs of the campaign done" in capsys.readouterr().out
    assert _campaign(tmp_path, "--campaign-shard", "2/2") == 0
    assert len(calls) == 4 and not set(first) & set(calls[2:])       # the shards split the plan
    printed = capsys.readouterr().out
    assert "4 of 4 runs of the campaign done" in printed
    assert "| occlude | 2 | 2 |" in printed and "| emergency | 2 | 2 |" in printed
    # a run lost mid-way (its result never written) is the only one a rerun makes
    lost = tmp_path / "c" / calls[1] / "result.json"
    lost.unlink()
    assert _campaign(tmp_path) == 0
    assert calls[4:] == [calls[1]]
    assert "3 already done in it" in capsys.readouterr().out
    table = (tmp_path / "c" / "campaign.md").read_text()
    assert table.startswith("4 of 4 runs")
    assert len(json.loads((tmp_path / "c" / "campaign.json").read_text())) == 4


def test_a_broken_run_is_failed_in_the_table_and_the_exit(tmp_path, monkeypatch, capsys):
    calls = []
    _fake_runs(monkeypatch, calls, fail_label="emergency_at7.1_line_s1")
    assert _campaign(tmp_path) == 1
    assert "emergency_at7.1_line_s1" in calls
    done = json.loads((tmp_path / "c" / "emergency_at7.1_line_s1" / "result.json").read_text())
    assert done["outcome"] == "failed" and "the twin broke" in done["stop_reason"]
    assert "| emergency | 2 | 1 | 0 | 1 |" in capsys.readouterr().out


def test_a_bad_shard_is_refused(tmp_path, capsys):
    for bad in ("3/2", "0/2", "a/b", "2"):
        try:
            _campaign(tmp_path, "--campaign-shard", bad)
        except SystemExit as exc:
            assert exc.code == 2
        assert f"--campaign-shard {bad}: expected K/N" in capsys.readouterr().err


def test_a_stopped_campaign_writes_the_table_of_what_is_done(tmp_path, monkeypatch, capsys):
    calls = []

    def run_path(args, path, out, faults=()):
        calls.append(out.parent.name)
        if len(calls) == 3:
            raise KeyboardInterrupt("SIGTERM")       # the twin's stop-signal handler
        return {"faults": {"outcome": "stopped", "stop_reason": "x", "stale_pulses": [], "recorder_lost": 0,
                           "per_fault": [{"fault": f.label(), "recovery_s": None} for f in faults]}}
    monkeypatch.setattr(twin, "run_path", run_path)
    assert _campaign(tmp_path) == 130
    printed = capsys.readouterr()
    assert "2 of 4 runs of the campaign done (the same command with --out" in printed.out
    assert "frog-twin: stopped (SIGTERM)" in printed.err
    assert (tmp_path / "c" / "campaign.md").read_text().startswith("2 of 4 runs")
    assert not (tmp_path / "c" / calls[2] / "result.json").exists()     # the interrupted run is redone


def test_the_full_campaign_is_three_moments_and_three_seeds_by_default(tmp_path, monkeypatch, capsys):
    calls = []
    _fake_runs(monkeypatch, calls)
    lib = tmp_path / "lib.npz"
    lib.touch()
    base = ["--fault-campaign", "--library", str(lib)]
    assert twin.main([*base, "--campaign-faults", "occlude@0+4", "--out", str(tmp_path / "a")]) == 0
    assert len(calls) == 1 * 3 * 3 * 2                  # fault x moments x seeds x (line, sine)
    assert {c.rsplit("_s", 1)[1] for c in calls} == {"1", "2", "3"}
    calls.clear()
    assert twin.main([*base, "--fault-classes", "--out", str(tmp_path / "b")]) == 0
    assert len(calls) == 6 * 2                          # the reduced form: one seed per class and path
