"""Per-limb kick strength (digital-twin realism): the curvature excursion scales, rest does not."""

import numpy as np
import pytest

from frog_sim.core.actuation import profile_value
from frog_sim.core.simulation import FrogSimulation


@pytest.fixture(scope="module")
def sim():
    return FrogSimulation()


def test_strength_scales_the_eq9_excursion_and_keeps_rest(sim):
    nominal = sim._actuator.limb_profile.copy()
    sim.set_limb_strength({"FL": 1.3, "BR": 0.7})
    try:
        rows = sim._actuator.limb_profile
        for lid, s in ((0, 1.3), (1, 1.0), (2, 1.0), (3, 0.7)):
            rest = profile_value(nominal[lid], -1.0)
            assert profile_value(rows[lid], -1.0) == pytest.approx(rest, abs=1e-12)
            for tau in np.linspace(0.0, nominal[lid, 9], 37):
                want = rest + s * (profile_value(nominal[lid], tau) - rest)
                assert profile_value(rows[lid], tau) == pytest.approx(want, rel=1e-9, abs=1e-9)
    finally:
        sim.set_limb_strength(None)
    np.testing.assert_array_equal(sim._actuator.limb_profile, nominal)


def test_a_weaker_left_side_turns_a_symmetric_kick(sim):
    """B (all four limbs) goes straight when nominal and turns toward the weak side otherwise."""
    headings = {}
    for label, strength in (("nominal", None), ("weak left", {"FL": 0.7, "BL": 0.7})):
        sim.reset()
        sim.set_limb_strength(strength)
        sim.execute_primitive("B")
        sim.step(int(round(1.5 / sim.time_step)))
        headings[label] = sim.rigid_body_state().heading
    sim.set_limb_strength(None)
    assert abs(headings["nominal"]) < 1e-6
    # weaker left limbs push less on the left: the body turns left (positive yaw, REP-103)
    assert headings["weak left"] > np.radians(0.5)


def test_bad_strengths_are_rejected(sim):
    for bad in ({"XX": 1.0}, {"FL": 0.0}, {"FR": float("nan")}):
        with pytest.raises(ValueError, match="limb strengths"):
            sim.set_limb_strength(bad)


def _b_kick(sim):
    """Heading change of one B from rest over 1.43 s [rad] (symmetric: 0 with equal kicks)."""
    sim.reset()
    sim.execute_primitive("B")
    sim.run(1.43, record_interval=0.05)
    return sim.rigid_body_state().heading


def test_kick_variability_varies_each_firing_and_is_off_by_default():
    sim = FrogSimulation()
    assert abs(_b_kick(sim)) < 1e-6                      # equal kicks: B goes straight
    sim.set_kick_variability(0.25, seed=3)
    turns = [_b_kick(sim) for _ in range(6)]
    # unequal left and right kicks turn a B, a different way each time, both ways
    assert len({round(t, 9) for t in turns}) == 6 and min(turns) < 0 < max(turns), turns
    assert all(0.2 <= f <= 2.0 for f in sim._firing_factor.values())
    # the same seed replays the same kicks; the factors act on the excursion only
    sim.set_kick_variability(0.25, seed=3)
    assert [_b_kick(sim) for _ in range(6)] == pytest.approx(turns, abs=1e-12)
    sim.set_kick_variability(0.0)
    assert abs(_b_kick(sim)) < 1e-6
    with pytest.raises(ValueError, match="kick variability"):
        sim.set_kick_variability(float("nan"))
