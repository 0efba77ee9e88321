"""Batched rollouts (core/rollouts.py) against the reference simulator, FrogSimulation.step.

Truth: ``FrogSimulation`` started from the same node state, with the same firings, stepped
with the same step sizes, gives the same trajectory (the rollouts run its own step kernel);
with its default step it is the reference the rollouts' coarser plan is bounded against.
The estimated start is checked against what the simulator reports of that state (pose,
twist, limb curvature) and against its own ``set_pose`` / ``set_velocity``.
"""
import math

import numpy as np
import pytest

from frog_sim.core.rod_network import discrete_curvature
from frog_sim.core.rollouts import Rollouts
from frog_common.primitives import LIMB_NAMES
from frog_sim.core.simulation import FrogSimulation

PERIOD = 1.43
POSE = (0.12, -0.05, 0.7)
TWIST = (0.025, -0.006, 0.25)
FIRED = {"FL": -0.3, "BL": -0.22}        # a C-like stroke 0.3 s before the decision


@pytest.fixture(scope="module")
def rollouts():
    return Rollouts(threads=2)


def reference(start, seq, period, plan=None, force_tolerance=None, ro=None):
    """FrogSimulation from ``start``'s node state and firings; per period end: (rigid state, nodes).

    ``plan``: per period [(n, h), ...] (as the rollouts step); None: the simulator's default step."""
    sim = FrogSimulation(force_tolerance=force_tolerance or 1e-6)
    sim.integrator.set_state(x=start.x, v=start.v)
    for lid, t in enumerate(start.last_firing):
        if np.isfinite(t):
            sim.fire_limbs([LIMB_NAMES[lid]], start=float(t))
    sim._unwrap.reset(start.pose[2])
    out = []
    for k, prim in enumerate(seq):
        sim.execute_primitive(prim, start=k * period)
        if plan is None:
            sim.step(int(round(period / sim.time_step)))
        else:
            for n, h in plan[k]:
                sim.time_step = h
                sim.step(n)
        out.append((sim.rigid_body_state(), sim.node_positions))
    return out


def body_frame(start_pose, state):
    c, s = math.cos(start_pose[2]), math.sin(start_pose[2])
    d = state.com - start_pose[:2]
    return np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1], state.heading - start_pose[2],
                     *state.body_velocity, state.yaw_rate])


def test_rollouts_take_the_steps_frog_simulation_takes(rollouts):
    start = rollouts.estimated_start(POSE, TWIST, FIRED)
    seqs = [("B",), ("E",), ("I",), ("C", "H"), ("A", "I"), ("I", "F")]
    res = rollouts.rollout_batch(start, seqs, period=PERIOD)
    assert res.converged.all() and res.stats["fallbacks"] == 0
    for b, seq in enumerate(seqs):
        plan = rollouts.step_plan(start, seq, PERIOD)
        ref = reference(start, seq, PERIOD, plan, force_tolerance=rollouts._sims[0].integrator.force_tolerance)
        for k, (state, nodes) in enumerate(ref):
            assert np.abs(res.ends[seq[:k + 1]].x.reshape(-1, 2) - nodes).max() < 1e-10, (seq, k)
            assert res.transitions[b, k] == pytest.approx(body_frame(start.pose, state), abs=1e-9), (seq, k)
            assert res.pose[b, k] == pytest.approx([*state.com, state.heading], abs=1e-9)


def test_the_step_plan_is_fine_in_the_kick_and_coarse_after(rollouts):
    start = rollouts.estimated_start(POSE, TWIST)
    (b_plan,) = rollouts.step_plan(start, "B", PERIOD)
    steps = np.concatenate([[h] * n for n, h in b_plan])
    assert steps.sum() == pytest.approx(PERIOD, abs=1e-12)
    fine = rollouts.kick_time_step
    # fine until kick_window after the rear firing (80 ms after the front), coarse after
    assert np.cumsum(steps)[steps == fine].max() == pytest.approx(0.08 + rollouts.kick_window, abs=fine)
    assert steps.max() <= rollouts.coast_time_step + 1e-15
    (i_plan,) = rollouts.step_plan(start, "I", PERIOD)       # nothing fires: coast all period
    assert len(i_plan) == 1 and i_plan[0][1] > fine


def test_rollouts_stay_close_to_the_default_time_step(rollouts):
    """The plan (2 ms kicks, <= 12 ms coast) and the rollouts' tolerance against uniform 2 ms
    steps at the simulator's tolerance: measured 0.07 mm / 0.08 deg at most (bench)."""
    start = rollouts.estimated_start(POSE, TWIST, FIRED)
    seqs = [("B",), ("D",), ("G",), ("I",)]
    res = rollouts.rollout_batch(start, seqs, period=PERIOD)
    for b, seq in enumerate(seqs):
        ((state, _),) = reference(start, seq, PERIOD)
        err = res.transitions[b, 0] - body_frame(start.pose, state)
        assert math.hypot(err[0], err[1]) < 0.3e-3, seq          # m
        assert abs(math.degrees(err[2])) < 0.2, seq
        assert np.abs(err[3:5]).max() < 0.3e-3, seq               # m/s
        assert abs(math.degrees(err[5])) < 0.5, seq               # deg/s


def test_relaxed_estimate_is_set_pose_and_set_velocity_of_the_simulator(rollouts):
    start = rollouts.estimated_start(POSE, TWIST)
    sim = FrogSimulation()
    sim.set_pose(*POSE)
    sim.set_velocity(*TWIST)
    assert np.abs(start.x.reshape(-1, 2) - sim.node_positions).max() < 1e-12
    assert np.abs(start.v.reshape(-1, 2) - sim.node_velocities).max() < 1e-12


def test_estimated_start_is_the_state_the_simulator_reports(rollouts):
    """Load the estimate into FrogSimulation: it reports the given pose, twist and the limb
    curvature of a limb fired 0.3 s ago (which the estimate's limb polygon has)."""
    truth = FrogSimulation()
    truth.fire_limbs(["FL"], start=0.0)
    truth.step(150)                                           # 0.3 s after the firing
    start = rollouts.estimated_start(POSE, TWIST, {"FL": 0.0, "BR": -1.0}, now=truth.time)
    sim = FrogSimulation()
    sim.integrator.set_state(x=start.x, v=start.v)
    sim.fire_limbs(["FL"], start=-0.3)
    sim.fire_limbs(["BR"], start=-1.3)
    sim.integrator.update_actuation(0.0)
    st = sim.rigid_body_state()
    assert st.com == pytest.approx(POSE[:2], abs=1e-12)
    assert math.remainder(st.heading - POSE[2], 2 * math.pi) == pytest.approx(0.0, abs=1e-12)
    assert st.body_velocity == pytest.approx(TWIST[:2], abs=1e-12)
    assert st.yaw_rate == pytest.approx(TWIST[2], abs=1e-12)
    assert sim.limb_curvatures["FL"] == pytest.approx(truth.limb_curvatures["FL"], rel=1e-9)
    assert sim.limb_curvatures["FL"] < 0.7 * sim.limb_curvatures["FR"]          # still far from relaxed
    model = sim.model
    for limb in ("FL", "BR", "FR"):
        bends = model.network.bends[model.limb_bends[limb]]
        geometric = discrete_curvature(start.x.reshape(-1, 2), bends, model.network.bend_length[model.limb_bends[limb]])
        assert geometric * model.limb_sign[limb] == pytest.approx(sim.limb_curvatures[limb], rel=1e-9), limb


def test_a_limb_fired_before_the_decision_is_relaxing_in_the_rollout(rollouts):
    """FL fired 0.3 s before the decision: over the next 0.4 s the rollout's FL curls back as
    the simulator's FL does (continued from its true state), not as a relaxed or fresh limb."""
    truth = FrogSimulation()
    truth.set_velocity(0.02, 0.0, 0.0)
    truth.fire_limbs(["FL"], start=0.0)
    truth.step(150)
    st = truth.rigid_body_state()
    pose, twist = [*st.com, st.heading], [*st.body_velocity, st.yaw_rate]
    model = truth.model
    net, bends = model.network, model.limb_bends["FL"]

    def fl_curvature(x):
        k = discrete_curvature(np.asarray(x).reshape(-1, 2), net.bends[bends], net.bend_length[bends])
        return float(np.mean(k) * model.limb_sign["FL"])
    c_truth_start = fl_curvature(truth.integrator.x)
    truth.step(200)                                           # to 0.7 s after the firing
    c_truth_end = fl_curvature(truth.integrator.x)
    informed = rollouts.rollout_batch(rollouts.estimated_start(pose, twist, {"FL": -0.3}), [("I",)], period=0.4)
    naive = rollouts.rollout_batch(rollouts.estimated_start(pose, twist), [("I",)], period=0.4)
    c_start = fl_curvature(rollouts.estimated_start(pose, twist, {"FL": -0.3}).x)
    c_end = fl_curvature(informed.ends[("I",)].x)
    relaxed = fl_curvature(naive.ends[("I",)].x)
    assert c_end - c_start > 20.0                            # curling back (1/m)
    assert c_truth_end - c_truth_start > 20.0
    assert abs(c_end - c_truth_end) < 0.15 * (c_truth_end - c_truth_start)
    assert abs(relaxed - c_truth_end) > 3 * abs(c_end - c_truth_end)
    # and the body moves as the simulator's does: closer than a start that ignores the firing
    truth_pose = np.array([*truth.rigid_body_state().com, truth.rigid_body_state().heading])
    err_informed = np.abs(informed.pose[0, 0] - truth_pose)
    err_naive = np.abs(naive.pose[0, 0] - truth_pose)
    assert err_informed[2] < err_naive[2] and np.hypot(*err_informed[:2]) < np.hypot(*err_naive[:2])


def test_depth_two_reuses_the_first_periods_and_threads_agree(rollouts):
    start = rollouts.estimated_start(POSE, TWIST, FIRED)
    seqs = [(a, b) for a in "ABCDEFGHI" for b in "ABCDEFGHI"]
    res = rollouts.rollout_batch(start, seqs, period=PERIOD)
    assert res.transitions.shape == (81, 2, 6) and res.converged.all()
    one = rollouts.rollout_batch(start, [(a,) for a in "ABCDEFGHI"], period=PERIOD)
    for b, (a, _) in enumerate(seqs):
        assert np.array_equal(res.transitions[b, 0], one.transitions["ABCDEFGHI".index(a), 0])
    # per start: 3 shared front strokes (A/B, C/E/G, D/F/H), the 8 rests after them, and I
    assert res.stats["jobs"] == (3 + 8 + 1) * (1 + 9)
    single = Rollouts(threads=1).rollout_batch(start, seqs[:20], period=PERIOD)
    assert np.array_equal(single.transitions, res.transitions[:20])
    # an end is a start (its own t = 0): continuing from it is the second period (to round-off)
    later = rollouts.rollout_batch(res.ends[("C",)], [("H",)], period=PERIOD)
    assert later.pose[0, 0] == pytest.approx(res.pose[seqs.index(("C", "H")), 1], abs=1e-9)


def test_a_decision_tree_coasts_the_lead_then_chains_each_period_from_the_last(rollouts):
    """decision_tree's rows against FrogSimulation.step driven with the same plan: the lead coasted
    with nothing fired, then each sequence; level 1 seen from the decision's pose (before the
    lead), level 2 from its parent's end; a beam leaves the other first primitives NaN."""
    start = rollouts.estimated_start(POSE, TWIST, FIRED)
    lead = 0.6
    rows, result = rollouts.decision_tree(start, PERIOD, depth=2, lead=lead, first_primitives=("C", "B"))
    assert rows.shape == (9 + 81, 6) and len(result.sequences) == 18
    names = "ABCDEFGHI"
    coast = rollouts.rollout_batch(start, [("I",)], period=lead).ends[("I",)]
    for first, second in (("B", "E"), ("C", "C")):
        plan = rollouts.step_plan(coast, (first, second), PERIOD)
        (one, _), (two, _) = reference(coast, (first, second), PERIOD, plan, force_tolerance=1e-4)
        lvl1 = rows[names.index(first)]
        lvl2 = rows[9 + 9 * names.index(first) + names.index(second)]
        np.testing.assert_allclose(lvl1, body_frame(np.asarray(POSE), one), atol=2e-6)
        parent = np.array([*one.com, one.heading])
        np.testing.assert_allclose(lvl2, body_frame(parent, two), atol=2e-6)
    np.testing.assert_allclose(result.lead_end.pose, coast.pose, atol=1e-12)
    # from the coast's end (the execution instant), level 1 is that end's own period
    from_end, _ = rollouts.decision_tree(start, PERIOD, depth=2, lead=lead, first_primitives=("C", "B"),
                                         from_lead_end=True)
    (one, _), = reference(coast, ("C",), PERIOD, rollouts.step_plan(coast, ("C",), PERIOD), force_tolerance=1e-4)
    np.testing.assert_allclose(from_end[2], body_frame(coast.pose, one), atol=2e-6)
    np.testing.assert_array_equal(from_end[9:], rows[9:])
    outside = [i for i, n in enumerate(names) if n not in "BC"]
    assert np.isnan(rows[outside]).all() and np.isfinite(rows[[1, 2]]).all()
    with pytest.raises(ValueError, match="lead"):
        rollouts.decision_tree(start, PERIOD, lead=-0.1)


def test_limbs_fired_at_any_time_and_limb_strengths_are_frog_simulation_s(rollouts):
    """run_firings against FrogSimulation.step with the same firings, steps and limb strengths: a C
    stroke fired 0.4 s into a 1.2 s window (as the bridge fires a decision made before it) with a
    weak FL and a strong BL; the nominal rollout differs by far more than the tolerance."""
    start = rollouts.estimated_start(POSE, TWIST, FIRED)
    strength = {"FL": 0.8, "BL": 1.25}
    firings = {"FL": 0.4, "BL": 0.48}
    try:
        rollouts.set_limb_strength(strength)
        assert rollouts.limb_strength == {"FL": 0.8, "FR": 1.0, "BL": 1.25, "BR": 1.0}
        weak = rollouts.estimated_start(POSE, TWIST, FIRED)
        end = rollouts.run_firings(weak, firings, 1.2)
    finally:
        rollouts.set_limb_strength(None)
    nominal = rollouts.run_firings(start, firings, 1.2)
    sim = FrogSimulation(force_tolerance=1e-4)
    sim.set_limb_strength(strength)
    sim.integrator.set_state(x=weak.x, v=weak.v)
    for lid, t in enumerate(weak.last_firing):
        if np.isfinite(t):
            sim.fire_limbs([LIMB_NAMES[lid]], start=float(t))
    for limb, t in firings.items():
        sim.fire_limbs([limb], start=t)
    sim._unwrap.reset(weak.pose[2])
    latest = max(firings.values())
    for n, h in rollouts.period_steps(0.0, 1.2, latest):
        sim.time_step = h
        sim.step(n)
    ref = sim.rigid_body_state()
    np.testing.assert_allclose(end.pose, [*ref.com, ref.heading], atol=2e-6)
    np.testing.assert_allclose(end.twist, [*ref.body_velocity, ref.yaw_rate], atol=2e-5)
    assert abs(nominal.pose[2] - end.pose[2]) > 100 * 2e-6
    with pytest.raises(ValueError, match="outside"):
        rollouts.run_firings(start, {"FL": 1.5}, 1.2)
    with pytest.raises(ValueError, match="unknown"):
        rollouts.run_firings(start, {"XX": 0.5}, 1.2)


def test_a_failed_fast_step_is_redone_as_frog_simulation_does():
    """With 3 Newton iterations the kick's fast steps fail: the job is redone with the
    integrator's step halving, and matches FrogSimulation (same limit) step for step."""
    ro = Rollouts(threads=2)
    for sim in ro._sims:
        sim.integrator.max_iterations = 3
    ro._solver = ro._sims[0].integrator._solver()
    start = ro.estimated_start(POSE, TWIST, FIRED)
    seq = ("C", "D")
    res = ro.rollout_batch(start, [seq, ("I",)], period=PERIOD)
    assert res.converged.all() and res.stats["fallbacks"] >= 1 and res.stats["failed"] == 0
    sim = FrogSimulation(force_tolerance=ro._sims[0].integrator.force_tolerance)
    sim.integrator.max_iterations = 3
    sim.integrator.set_state(x=start.x, v=start.v)
    for lid, t in enumerate(start.last_firing):
        if np.isfinite(t):
            sim.fire_limbs([LIMB_NAMES[lid]], start=float(t))
    for k, (prim, plan) in enumerate(zip(seq, ro.step_plan(start, seq, PERIOD))):
        sim.execute_primitive(prim, start=k * PERIOD)
        for n, h in plan:
            sim.time_step = h
            sim.step(n)
    assert sim.integrator.stats.halvings > 0
    assert np.abs(res.ends[seq].x - sim.integrator.x).max() < 1e-10


def test_bad_input_is_named(rollouts):
    good = rollouts.estimated_start(POSE, TWIST)
    with pytest.raises(ValueError, match="pose"):
        rollouts.estimated_start((0.0, float("nan"), 0.0), TWIST)
    with pytest.raises(ValueError, match="twist"):
        rollouts.estimated_start(POSE, (0.0, 0.0))
    with pytest.raises(ValueError, match="limb 'XL' is unknown"):
        rollouts.estimated_start(POSE, TWIST, {"XL": -0.1})
    with pytest.raises(ValueError, match="after now"):
        rollouts.estimated_start(POSE, TWIST, {"FL": 0.5}, now=0.2)
    with pytest.raises(ValueError, match="primitive 'Z' is unknown"):
        rollouts.rollout_batch(good, [("A", "Z")], period=PERIOD)
    with pytest.raises(ValueError, match="primitive id 9"):
        rollouts.rollout_batch(good, [(9,)], period=PERIOD)
    for period in (-1.43, 0.0, float("nan"), 6.0):
        with pytest.raises(ValueError, match="period"):
            rollouts.rollout_batch(good, [("A",)], period=period)
    with pytest.raises(ValueError, match="non-empty"):
        rollouts.rollout_batch(good, [], period=PERIOD)
    with pytest.raises(ValueError, match="coast_time_step"):
        Rollouts(kick_time_step=0.004, coast_time_step=0.002)
