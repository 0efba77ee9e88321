"""Online limb-strength identification (core/limb_identification.py) against a simulated robot whose
limbs are known: ``FrogSimulation`` with ``set_limb_strength`` is the truth the estimate must find
from the tracked pose, twist and firing times alone."""

import math

import numpy as np
import pytest

from frog_common.primitives import LIMB_NAMES
from frog_sim.core.limb_identification import LimbIdentification
from frog_sim.core.rollouts import Rollouts
from frog_sim.core.simulation import FrogSimulation
from frog_sim.core.yaw_disturbance import TANK_YAW_TORQUE_SD

PERIOD = 1.43
TRUTH = {"FL": 1.2, "FR": 0.75, "BL": 1.1, "BR": 0.95}


@pytest.fixture(scope="module")
def rollouts():
    with Rollouts(threads=1) as ro:
        yield ro


def observed(sim):
    """What a robot's planner knows now: tracked pose and twist, and each limb's last firing."""
    st = sim.rigid_body_state()
    return sim.time, [*st.com, st.heading], [*st.body_velocity, st.yaw_rate], sim.last_firings()


def swim(ident, sim, primitives, lead=0.0):
    """Decide (observe) each period and fire ``lead`` s later, as planner_node does."""
    steps = int(round(PERIOD / sim.time_step))
    lead_steps = int(round(lead / sim.time_step))
    for prim in primitives:
        ident.start(*observed(sim))
        sim.step(lead_steps)
        sim.execute_primitive(prim)
        sim.step(steps - lead_steps)


def test_last_firings_are_what_fired_up_to_now():
    """C fires FL now and BL, BR one pulse later (DESIGN.md: front first); a firing still to come
    is not known yet."""
    sim = FrogSimulation()
    assert sim.last_firings() == {}
    sim.execute_primitive("C")
    assert sim.last_firings() == {"FL": 0.0}
    pulse = sim.params.pulse_duration
    sim.step(int(round((pulse + 0.02) / sim.time_step)))
    assert sim.last_firings() == pytest.approx({"FL": 0.0, "BL": pulse, "BR": pulse})


@pytest.mark.parametrize("lead", [0.0, 0.3])
@pytest.mark.slow
def test_the_limbs_of_a_simulated_robot_are_found(rollouts, lead):
    """Twenty periods of turning and straight kicks: each limb's estimate within 0.06 of the truth
    (a prior of 1 +- 0.1; the sd says how sure it is), and the rollouts believe in it."""
    sim = FrogSimulation()
    sim.set_limb_strength(TRUTH)
    ident = LimbIdentification(rollouts)
    swim(ident, sim, "BCDBEFBGHBCDBEFBGHBB", lead)
    assert ident.updates == 19
    for limb, want in TRUTH.items():
        assert ident.strengths[limb] == pytest.approx(want, abs=0.06), (limb, ident.strengths)
        assert ident.sd[limb] < 0.06
    ident.start(*observed(sim))
    assert rollouts.limb_strength == pytest.approx(ident.strengths)


@pytest.mark.slow
def test_the_limbs_are_found_while_estimating_a_tank_torque_too(rollouts):
    """rollout_node's default: the filter also carries the tank's yaw torque. In a calm tank the
    limbs are still found within 0.06 (a lasting turn is the limbs', not the torque's, which
    fades within 1.25 s) and the torque estimate stays within one sd of 0."""
    sim = FrogSimulation()
    sim.set_limb_strength(TRUTH)
    ident = LimbIdentification(rollouts, torque_sd=TANK_YAW_TORQUE_SD)
    swim(ident, sim, "BCDBEFBGHBCDBEFBGHBB")
    assert ident.updates == 19
    for limb, want in TRUTH.items():
        assert ident.strengths[limb] == pytest.approx(want, abs=0.06), (limb, ident.strengths)
    assert abs(ident.torque) < TANK_YAW_TORQUE_SD, ident.torque


def test_a_nominal_robot_stays_nominal_and_nothing_fired_teaches_nothing(rollouts):
    sim = FrogSimulation()
    ident = LimbIdentification(rollouts)
    swim(ident, sim, "BCDBEFBGH")
    assert all(v == pytest.approx(1.0, abs=0.03) for v in ident.strengths.values()), ident.strengths
    still = LimbIdentification(rollouts)
    swim(still, FrogSimulation(), "IIII")            # no firing, no limb relaxing: no update
    assert still.updates == 0 and still.strengths == {limb: 1.0 for limb in LIMB_NAMES}


def test_observations_too_far_apart_or_backwards_are_not_compared(rollouts):
    ident = LimbIdentification(rollouts, max_gap=2.0)
    sim = FrogSimulation()
    now, pose, twist, fired = observed(sim)
    ident.start(now, pose, twist, fired)
    sim.execute_primitive("C")
    sim.step(int(round(2.5 / sim.time_step)))
    ident.start(*observed(sim))                       # 2.5 s later: a missed decision
    ident.start(*observed(sim))                       # the same instant again
    assert ident.updates == 0
    ident.reset()
    assert ident.strengths == {limb: 1.0 for limb in LIMB_NAMES} and ident.updates == 0


def test_bad_settings_are_named(rollouts):
    with pytest.raises(ValueError, match="noise"):
        LimbIdentification(rollouts, noise=(0.1, 0.1, 0.1))
    with pytest.raises(ValueError, match="prior_sd"):
        LimbIdentification(rollouts, prior_sd=math.nan)
    assert np.isfinite(LimbIdentification(rollouts).cov).all()
