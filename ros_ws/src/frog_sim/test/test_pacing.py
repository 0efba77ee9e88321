"""The simulator's pacing against the wall clock (core/pacing.py), driven by a fake wall clock.

Truth: at real-time factor r the world is at r * (wall seconds since the anchor); a lag up to
max_lag_s (wall) is caught up in full; a longer one is dropped, after which the world again
advances r simulated seconds per wall second and never more than the threshold faster.
"""
import math

import pytest

from frog_sim.core.pacing import Pacer


def _run(pacer, walls, sim=0.0, capacity=math.inf, stalled=()):
    """Step a world to the pacer's target at each wall time (at most ``capacity`` simulated s per
    tick; nothing at the ``stalled`` ones: the process blocked). [(wall, sim after the tick)]."""
    out = []
    for w in walls:
        if w not in stalled:
            target, _ = pacer.target(w, sim)
            sim = min(target, sim + capacity)
        out.append((w, sim))
    return out


def _ticks(t0, t1, dt=0.01):
    return [round(t0 + k * dt, 10) for k in range(int(round((t1 - t0) / dt)) + 1)]


@pytest.mark.parametrize("rtf", [1.0, 2.5])
def test_on_time_the_world_is_at_rtf_times_the_wall(rtf):
    p = Pacer(rtf, 0.5)
    p.anchor(100.0, 3.0)
    for w, s in _run(p, _ticks(100.0, 102.0), sim=3.0):
        assert s == pytest.approx(3.0 + rtf * (w - 100.0), abs=1e-9)
    assert p.drops == 0 and p.achieved_rtf(102.0, 3.0 + 2 * rtf) == pytest.approx(rtf)


def test_a_short_lag_is_caught_up_in_full():
    p = Pacer(1.0, 0.5)
    p.anchor(0.0, 0.0)
    walls = _ticks(0.0, 2.0)
    stalled = {w for w in walls if 1.0 < w < 1.4}          # 0.4 s blocked: under the bound
    run = dict(_run(p, walls, stalled=stalled))
    assert run[1.39] == pytest.approx(1.0, abs=1e-9)       # stood while blocked
    assert run[1.4] == pytest.approx(1.4, abs=1e-9)        # then caught up at once
    assert run[2.0] == pytest.approx(2.0, abs=1e-9) and p.drops == 0


@pytest.mark.parametrize("rtf,max_lag", [(1.0, 0.5), (1.0, 0.2), (3.0, 0.5)])
def test_a_long_stall_is_dropped_and_the_world_goes_on_at_rtf(rtf, max_lag):
    p = Pacer(rtf, max_lag)
    p.anchor(0.0, 0.0)
    walls = _ticks(0.0, 6.0)
    stalled = {w for w in walls if 1.0 < w < 3.5}          # 2.5 s blocked (the CI run's sim_node)
    run = _run(p, walls, stalled=stalled)
    at = dict(run)
    assert at[3.5] == pytest.approx(at[1.0], abs=1e-9) == pytest.approx(rtf * 1.0, abs=1e-9)   # no race
    assert p.drops == 1 and p.dropped_total_s == pytest.approx(rtf * 2.5, abs=1e-9)
    # afterwards r simulated seconds per wall second, from where it stood
    for w, s in run:
        if w >= 3.5:
            assert s == pytest.approx(rtf * (1.0 + (w - 3.5)), abs=1e-9)
    # never faster than r, plus a lag under the bound, over any wall second
    for (w0, s0), (w1, s1) in zip(run, run[100:]):
        assert s1 - s0 <= rtf * (w1 - w0 + max_lag) + 1e-9
    assert p.achieved_rtf(6.0, at[6.0]) == pytest.approx(rtf * 3.5 / 6.0)


def test_max_lag_zero_always_catches_up():
    p = Pacer(1.0, 0.0)
    p.anchor(0.0, 0.0)
    walls = _ticks(0.0, 4.0)
    at = dict(_run(p, walls, stalled={w for w in walls if 1.0 < w < 3.5}))
    assert at[3.5] == pytest.approx(3.5, abs=1e-9) and p.drops == 0


def test_a_world_slower_than_rtf_runs_as_fast_as_it_computes():
    p = Pacer(10.0, 0.5)
    p.anchor(0.0, 0.0)
    run = _run(p, _ticks(0.0, 3.0), capacity=0.02)        # 2 simulated s per wall s: it cannot keep up
    # a full step every tick but the first (target 0) and those that dropped the lag (target: here)
    assert p.drops >= 3      # the lag grows 8 simulated s per wall s: past 5 (0.5 wall s) every ~0.6 s
    assert run[-1][1] == pytest.approx(0.02 * (len(run) - 1 - p.drops), abs=1e-6)


def test_anchor_and_as_fast_as_possible():
    p = Pacer(0.0, 0.5)
    assert p.target(5.0, 1.0) == (math.inf, 0.0)
    p = Pacer(1.0, 0.5)
    p.anchor(0.0, 0.0)
    _run(p, _ticks(0.0, 3.0), stalled=set(_ticks(0.5, 2.0)))
    p.anchor(10.0, 2.0)                                     # a resume: no jump, nothing dropped since
    assert p.target(10.0, 2.0) == (2.0, 0.0) and p.dropped_s == 0.0 and p.drops == 1


@pytest.mark.parametrize("rtf,lag", [(-1.0, 0.5), (1.0, -0.1), (math.nan, 0.5), (1.0, math.inf)])
def test_bad_values_named(rtf, lag):
    with pytest.raises(ValueError, match="max_lag_s"):
        Pacer(rtf, lag)
