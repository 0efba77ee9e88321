"""Scheduler, limb protection and link supervision (no ROS)."""

import numpy as np
import pytest

from soft_robot_common.link_state import LinkState, LinkSupervisor
from frog_bridge.core.protection import LimbGuard, PlannedPulse, ProtectionConfig
from frog_bridge.core.schedule import (
    CANCELLED_OVERLAP, REFUSED_DUTY, REFUSED_INTERVAL, REFUSED_INVALID, REFUSED_STATE_AGE, CommandScheduler)

P = 0.08
B, C, D, H, I_ = 1, 2, 3, 7, 8


def sched(interval=0.8, duty=0.10, window=10.0, age=0.5):
    return CommandScheduler(LimbGuard(ProtectionConfig(interval, duty, window)), P, age)


def run(s, now):
    """Write everything due by ``now`` (as the node does) and return (due, limbs) pairs."""
    out, _stale = s.pop_due(now)
    for p in out:
        s.written(p, p.due)
    return [(round(p.due, 6), p.limbs) for p in out]


def test_primitive_front_now_rear_one_pulse_later():
    s = sched()
    d = s.submit_primitive(B, stamp=9.99, now=10.0)
    assert d.accepted
    assert [(p.due, p.limbs) for p in d.pulses] == [(10.0, (1, 0)), (pytest.approx(10.08), (2, 3))]
    assert run(s, 10.0) == [(10.0, (1, 0))]
    assert s.next_due() == pytest.approx(10.08)
    assert run(s, 10.081) == [(10.08, (2, 3))]
    assert s.submit_primitive(I_, 0.0, 11.0).pulses == []       # I sends nothing


def test_too_fast_repeat_is_refused_whole_and_counted():
    s = sched()
    s.submit_primitive(B, 0.0, 0.0)
    run(s, 0.1)
    d = s.submit_primitive(D, 0.0, 0.5)            # FR again after 0.5 s < 0.8 s
    assert not d.accepted and d.refused == REFUSED_INTERVAL and "FR" in d.reason
    assert s.pending == []                          # nothing of D is scheduled (no rear only)
    assert s.counts[REFUSED_INTERVAL] == 1
    assert s.submit_primitive(D, 0.0, 0.81).accepted   # the limit, not a lockout


def test_duty_cycle_bound_is_a_sliding_window():
    # interval off; 20 % duty over 1 s allows two 80 ms pulses per second per limb
    s = sched(interval=0.0, duty=0.2, window=1.0)
    t, accepted = 0.0, 0
    for _ in range(5):                               # H (FR) every 0.1 s
        d = s.submit_primitive(H, 0.0, t)
        accepted += d.accepted
        run(s, t)
        t += 0.1
    assert accepted == 2
    assert s.counts[REFUSED_DUTY] == 3
    # after the window has passed the limb may be heated again
    assert s.submit_primitive(H, 0.0, 1.25).accepted


def test_default_limits_let_the_authors_gait_through():
    """1.2 Hz (the fastest cycle of the 10 % limbs) and the planner's 1.43 s pass for 60 s."""
    for period in (1 / 1.2, 1.43, 1.125):
        s = sched()
        t = 0.0
        while t < 60:
            assert s.submit_primitive(B, 0.0, t).accepted, (period, t)
            run(s, t + 0.2)
            t += period
    # but a sustained 0.8 s train is cut by the duty bound (80 ms / 0.8 s = 10 % > 9.6 %)
    s = sched()
    results = []
    for k in range(40):
        results.append(s.submit_primitive(H, 0.0, 0.8 * k).accepted)
        run(s, 0.8 * k)
    assert all(results[:12]) and not all(results)


def test_new_primitive_cancels_a_pending_rear_only_if_they_overlap():
    s = sched(interval=0.0, duty=1.0)
    s.submit_primitive(B, 0.0, 0.0)
    run(s, 0.0)                                      # B's rear (BL, BR) pending at 0.08
    d = s.submit_primitive(H, 0.0, 0.03)            # H: FR only: no overlap
    assert d.accepted and d.cancelled == []
    run(s, 0.03)
    d = s.submit_primitive(C, 0.0, 0.05)            # C's rear BL+BR at 0.13 overlaps B's rear
    assert d.accepted and [p.label for p in d.cancelled] == ["B rear"]
    assert s.counts[CANCELLED_OVERLAP] == 1
    assert [p.label for p in s.pending] == ["C front", "C rear"]
    # a refused command cancels nothing
    s = sched()
    s.submit_primitive(B, 0.0, 0.0)
    run(s, 0.0)
    d = s.submit_primitive(B, 0.0, 0.05)
    assert not d.accepted and [p.label for p in s.pending] == ["B rear"]


def test_a_command_on_a_stale_state_is_refused_whole_and_never_replayed():
    s = sched(age=0.5)
    # the state is the command's state stamp; B's rear pair is due one pulse later: 0.45 + 0.08 > 0.5
    d = s.submit_primitive(B, stamp=2.0, now=2.0, state_stamp=1.55)
    assert d.refused == REFUSED_STATE_AGE and "0.530 s old" in d.reason and s.pending == []
    # a primitive whose pairs both fire within the bound is accepted (H: front only, due now)
    assert s.submit_primitive(H, stamp=2.0, now=2.0, state_stamp=1.55).accepted
    # without a state stamp the header stamp is the state; with neither, now
    d = s.submit_primitive(B, stamp=1.0, now=3.0)
    assert d.refused == REFUSED_STATE_AGE and "2.080 s old" in d.reason
    d = s.submit_limbs([2], 0.0, 3.0, state_stamp=10.0)
    assert d.refused == REFUSED_STATE_AGE and "future" in d.reason
    assert s.submit_limbs([3], 0.0, 3.0).accepted
    # a pending pulse whose state has grown too old by its write (a blocked executor) is dropped
    s = sched(age=0.5)
    s.submit_primitive(B, stamp=3.0, now=3.0, state_stamp=2.9)
    out, stale = s.pop_due(3.45)
    assert out == [] and [p.label for p in stale] == ["B front", "B rear"] and s.counts[REFUSED_STATE_AGE] == 2
    assert s.pop_due(10.0) == ([], []) and s.pending == []          # nothing comes back later


def test_no_pulse_is_ever_written_on_a_state_older_than_the_bound():
    """Property: random commands on random state ages, written by timers that run late; every
    pulse written satisfies write time - state stamp <= max_state_age_s."""
    rng = np.random.default_rng(3)
    bound = 0.5
    s = CommandScheduler(LimbGuard(ProtectionConfig(0.0, 1.0, 10.0)), P, bound)
    t, written, refused = 0.0, 0, 0
    for _ in range(4000):
        t += float(rng.exponential(0.1))
        for p in s.pop_due(t)[0]:
            assert t - p.state <= bound + 1e-12
            written += 1
        age = float(rng.uniform(0.0, 0.8))
        d = s.submit_primitive(int(rng.integers(8)), t, t, state_stamp=t - age)
        refused += not d.accepted
    assert written > 1000 and refused > 1000


def test_invalid_limb_commands():
    s = sched()
    for limbs in ([], [0, 0], [4]):
        assert s.submit_limbs(limbs, 0.0, 0.0).refused == REFUSED_INVALID
    assert s.submit_primitive(9, 0.0, 0.0).refused == REFUSED_INVALID
    d = s.submit_limbs([0, 2], 0.0, 0.0)
    assert d.accepted and d.pulses[0].limbs == (0, 2)


def test_non_finite_or_negative_pulse_length_is_refused_not_fired():
    # abs(nan - 0.08) > tol is False: a NaN must not pass as "close to the bridge's pulse"
    s = sched()
    for bad in (float("nan"), float("inf"), -float("inf"), -1.0, 0.2):
        d = s.submit_limbs([1], 0.0, 0.0, pulse_s=bad)
        assert d.refused == REFUSED_INVALID and "pulse_duration" in d.reason, bad
    assert s.pending == [] and s.counts[REFUSED_INVALID] == 5
    assert s.submit_limbs([1], 0.0, 0.0, pulse_s=P).accepted
    assert s.submit_limbs([2], 0.0, 0.0, pulse_s=0.0).accepted


def test_guard_clock_jump_back_clears_history():
    g = LimbGuard(ProtectionConfig(0.8, 0.1, 10.0))
    g.record(PlannedPulse(100.0, (0,), P))
    assert g.check([PlannedPulse(100.5, (0,), P)])
    g.record(PlannedPulse(1.0, (1,), P))              # simulator reset: time 100 -> 1
    assert g.check([PlannedPulse(1.0, (0,), P)]) is None


def test_random_commands_never_break_the_limits():
    """Property: whatever is submitted, written pulses per limb respect both limits."""
    rng = np.random.default_rng(7)
    cfg = ProtectionConfig(0.8, 0.1, 10.0)
    s = CommandScheduler(LimbGuard(cfg), P, 0.5)
    written = {i: [] for i in range(4)}
    t = 0.0
    for _ in range(3000):
        t += float(rng.exponential(0.15))
        for p in s.pop_due(t)[0]:
            s.written(p, p.due)
            for limb in p.limbs:
                written[limb].append(p.due)
        if rng.random() < 0.7:
            s.submit_primitive(int(rng.integers(9)), 0.0, t)
        else:
            s.submit_limbs(list(rng.choice(4, size=rng.integers(1, 4), replace=False)), 0.0, t)
    for limb, starts in written.items():
        starts = np.array(starts)
        assert len(starts) > 50
        assert np.diff(starts).min() >= 0.8 - 1e-9
        for t0 in starts:                            # any window ending at a pulse end
            inside = starts[(starts > t0 + P - 10.0 - P) & (starts <= t0)]
            assert len(inside) * P / 10.0 <= 0.1 + 1e-9


def test_link_state_machine_and_backoff():
    link = LinkSupervisor(reconnect_period_s=0.5, reconnect_max_period_s=2.0, settle_s=0.2,
                          stall_timeout_s=1.0)
    assert link.state is LinkState.DISCONNECTED and link.should_attempt(0.0)
    delays = []
    t = 0.0
    for _ in range(5):
        link.open_failed(t, "no such file")
        delays.append(link.next_attempt - t)
        t = link.next_attempt
    assert delays == [0.5, 1.0, 2.0, 2.0, 2.0]
    link.opened(t)
    assert link.state is LinkState.CONNECTING and not link.can_actuate
    assert not link.settled(t + 0.1) and link.settled(t + 0.2)
    link.ready(t + 0.2)
    assert link.can_actuate and link.failures == 0
    assert not link.stalled(t + 1.0) and link.stalled(t + 1.3)
    link.line_received(t + 1.3)
    assert not link.stalled(t + 1.4) and link.line_age(t + 1.4) == pytest.approx(0.1)
    assert link.emergency("Central: EMERGENCY") and not link.emergency("again")
    assert link.state is LinkState.EMERGENCY and not link.can_actuate
    link.lost(t + 2.0, "EIO")                      # the latch survives a disconnect
    assert link.state is LinkState.EMERGENCY and link.next_attempt == pytest.approx(t + 2.5)
    assert link.clear_emergency() and link.state is LinkState.DISCONNECTED
    assert not link.clear_emergency()
    with pytest.raises(ValueError):
        LinkSupervisor(reconnect_period_s=2.0, reconnect_max_period_s=1.0)


def test_watchdog_trips_once_after_the_silence_and_a_fresh_primitive_clears_it():
    from frog_bridge.core.watchdog import PrimitiveWatchdog
    w = PrimitiveWatchdog(3.0)
    assert not w.check(100.0) and w.silence(100.0) is None           # not armed before the first primitive
    assert not w.fed(100.0)
    assert w.silence(100.5) == pytest.approx(0.5)
    assert [w.check(t) for t in (101.0, 102.99, 103.01, 103.5, 200.0)] == [False, False, True, False, False]
    assert w.tripped and w.trips == 1
    assert w.fed(200.1) and not w.tripped                            # the next primitive clears it
    assert not w.fed(200.2)
    assert not w.check(203.1) and w.check(203.3) and w.trips == 2
    assert w.fed(203.4)
    assert not w.check(6.0) and not w.check(8.9) and w.check(9.1)    # clock back (new simulator): start over
    w.timeout_s = 0.5
    assert w.fed(9.2) and not w.check(9.7) and w.check(9.8)
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(ValueError, match="timeout"):
            PrimitiveWatchdog(bad)


def test_watchdog_cancels_the_pending_rear_pulse_on_a_fake_clock():
    """The node's use: a primitive, then silence; at the rear pulse's due time the watchdog is checked
    first, cancels the rear through the scheduler, and a fresh primitive afterwards fires normally."""
    from frog_bridge.core.schedule import CANCELLED_WATCHDOG
    from frog_bridge.core.watchdog import PrimitiveWatchdog
    s = CommandScheduler(LimbGuard(ProtectionConfig(0.0, 1.0, 10.0)), 0.5, 0.5)   # 500 ms pulses
    w = PrimitiveWatchdog(0.2)
    s.submit_primitive(B, 10.0, 10.0)
    w.fed(10.0)
    assert run(s, 10.0) == [(10.0, (1, 0))]
    written = []
    for now in np.arange(10.05, 11.0, 0.05):                         # the node's timers
        if w.check(now):
            assert [p.label for p in s.cancel_all(CANCELLED_WATCHDOG)] == ["B rear"]
        written += run(s, now)
    assert written == [] and s.counts[CANCELLED_WATCHDOG] == 1 and w.tripped
    assert s.submit_primitive(B, 11.0, 11.0).accepted and w.fed(11.0)
    assert run(s, 11.0) + run(s, 11.5) == [(11.0, (1, 0)), (11.5, (2, 3))]


@pytest.mark.parametrize("kw, message", [({"max_duty_cycle": 0.0}, "max_duty_cycle=0.0 is below its minimum 0.001"),
                                         ({"min_limb_interval_s": float("nan")}, "min_limb_interval_s=nan must be"),
                                         ({"duty_window_s": 0.05}, "duty_window_s=0.05 is below its minimum 0.1")])
def test_protection_limits_out_of_range_are_refused_by_name(kw, message):
    with pytest.raises(ValueError, match=message):
        ProtectionConfig(**kw)


@pytest.mark.parametrize("timeout_s", [0.05, 0.2, 0.49, 0.51, 1.0, 3.0])
def test_timeout_problem_names_exactly_the_timeouts_that_cancel_every_rear(timeout_s):
    """The warning is given iff a primitive's own rear pair (due one pulse after it) meets a
    tripped watchdog, checked by running the watchdog itself with the bridge's 10 ms timer."""
    from frog_bridge.core.watchdog import PrimitiveWatchdog, timeout_problem
    rear_delay = 0.5
    w = PrimitiveWatchdog(timeout_s)
    w.fed(100.0)
    tripped_before_rear = any(w.check(100.0 + k * 0.01) for k in range(1, 51))
    problem = timeout_problem(timeout_s, rear_delay)
    assert (problem is not None) == tripped_before_rear
    if problem:
        assert f"{timeout_s:g} s" in problem and "0.5 s" in problem and "pulse_ms" in problem
