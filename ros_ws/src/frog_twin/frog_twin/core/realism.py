"""The digital twin's robot: how the simulated frog differs from the nominal model, defined once.

``frog-twin`` passes these to ``sim_node`` (each switchable on its command line), and the
in-process evaluator (``frog-planner-eval --twin-seed``) applies them with the same seed, so
both simulate the same robot (``FrogSimulation.set_realism``).
"""

from __future__ import annotations

from dataclasses import dataclass

from frog_sim.core.yaw_disturbance import TANK_YAW_TORQUE_SD, TANK_YAW_TORQUE_TAU_S

HARDWARE_PERIOD_S = 1.43     # decision period measured in the authors' closed-loop logs
LIMB_STRENGTH_SD = 0.1       # relative spread of the four limbs' kick strengths (real limbs differ)
# The robot's heading per period varies about the model's (4.3 deg sd, correlated over 1-2
# periods): a slowly varying yaw torque (frog_sim.core.yaw_disturbance) and a small
# per-firing kick spread, identified jointly on the hardware runs' residual autocovariance
# by `frog-sim disturbance` (runs/disturbance; frog_twin test_kick_variability.py checks them);
# the yaw torque's values are frog_sim's, where the planner's rollouts estimate it too
KICK_STRENGTH_SD = 0.05
YAW_DISTURBANCE_SD = TANK_YAW_TORQUE_SD          # [N m]
YAW_DISTURBANCE_TAU_S = TANK_YAW_TORQUE_TAU_S    # [s]


@dataclass(frozen=True)
class Realism:
    """One simulated robot: the seed and the spreads of ``FrogSimulation.set_realism``."""

    seed: int = 1
    limb_strength_sd: float = LIMB_STRENGTH_SD
    kick_strength_sd: float = KICK_STRENGTH_SD
    yaw_disturbance_sd: float = YAW_DISTURBANCE_SD
    yaw_disturbance_tau: float = YAW_DISTURBANCE_TAU_S

    def apply(self, sim) -> dict:
        """Make ``sim`` (a FrogSimulation) this robot; returns its limb strengths."""
        return sim.set_realism(self.seed, self.limb_strength_sd, self.kick_strength_sd, self.yaw_disturbance_sd,
                               self.yaw_disturbance_tau)
