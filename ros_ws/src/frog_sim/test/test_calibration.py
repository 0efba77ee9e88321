"""Joint calibration: objective terms by hand and a known-answer search."""
import pytest

from frog_sim import calibration as cal
from frog_sim.core.hardware_runs import Transition
from frog_sim.core.model_parameters import FrogParameters
from frog_sim.core.simulation import FrogSimulation
from frog_sim.fidelity import simulate_transition


def _truth_targets(params, states):
    sim = FrogSimulation(params)
    out = {}
    for p, (u, v, r) in states.items():
        s = simulate_transition(sim, Transition("t", 0, 0.0, 1.43, p, "", u, v, r, 0, 0, 0), 0.1)
        out[p] = cal.PrimitiveTarget(p, 5, 1.43, u, v, r, s.dx, s.dy, s.dheading)
    return out


def test_primitive_targets_are_means():
    trs = [Transition("r", k, 0.0, 1.4, "E", "", 0.01 * k, 0.0, 0.0, 0.02 * k, -0.01, -0.2) for k in range(1, 4)]
    t = cal.primitive_targets(trs)["E"]
    assert t.n == 3 and t.forward == pytest.approx(0.02) and t.dx == pytest.approx(0.04)
    assert t.dheading == pytest.approx(-0.2) and "B" not in cal.primitive_targets(trs)


def test_terms_are_one_at_the_tolerance():
    targets = {p: cal.PrimitiveTarget(p, 1, 1.4, 0, 0, 0, 0.04, 0.02, 0.2) for p in "BCDEF"}
    obj = cal.JointObjective.__new__(cal.JointObjective)
    obj.targets = targets
    sim = {"transitions": {p: {"dx": 0.04 * 1.15, "dy": 0.02 * 0.65, "dheading": 0.2 * 1.25} for p in "BCDEF"},
           "kick_ratio_at_1p5s": 0.6}
    terms = obj.terms(sim)
    for k in ("dheading_C", "dheading_D", "dheading_E", "dheading_F", "dy_E", "dy_F", "dx_B", "yaw_decay"):
        assert terms[k] == pytest.approx(1.0), k


def test_grid_search_recovers_a_known_limb_width():
    """Synthetic 'real' transitions made with w = 16 mm: the grid picks it, the transition terms vanish."""
    base = FrogParameters().replace(**cal.PHYSICAL_BASE, limb_root_angle_deg=-75.0, front_root_angle_offset_deg=60.0)
    truth = base.replace(limb_fluid_width=0.016)
    targets = _truth_targets(truth, {"B": (0.013, 0.0, 0.0), "E": (0.013, -0.003, 0.04), "F": (0.012, 0.006, -0.02)})
    obj = cal.JointObjective(targets, [], [], base, speeds=False)
    best, history = cal.coarse_to_fine(obj, {"limb_fluid_width": (0.010, 0.016, 0.022)})
    assert best.values["limb_fluid_width"] == pytest.approx(0.016)
    for k, v in best.terms.items():
        if k.startswith(("dheading", "dy", "dx")):
            assert v < 1e-12, k
    costs = {round(ev.values["limb_fluid_width"], 3): ev.cost for _, ev in history}
    assert costs[0.016] < costs[0.010] and costs[0.016] < costs[0.022]
    # cached: a second call simulates nothing new
    assert obj({"limb_fluid_width": 0.016}) is best
