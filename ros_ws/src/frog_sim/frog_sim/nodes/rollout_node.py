"""``rollout_node``: the DER simulator as a transition model for the planner.

Service ``frog/rollouts`` (soft_robot_interfaces/Rollouts): from the robot's estimated
state (tracked pose, body twist, and how long ago each limb was fired) it rolls out every
primitive sequence of depth 1 or 2 (9 or 81; shared prefixes are simulated once) with
:class:`frog_sim.core.rollouts.Rollouts` and returns the transitions level by level, in the
layout of the motion library: ``planner_node`` with ``transitions:=simulator`` chains them
by eq. 18 exactly as it chains library transitions. The model is compiled and warmed up at
start-up (``ready`` in the log and on ``diagnostics``), so the first request is as fast as
the others. ``lead`` first coasts the estimated state (nothing fired, limbs relaxing) for the
time until the decision will be executed, so the tree starts where the robot will be when
it fires; ``first_primitives`` restricts depth 2 to a beam (the other rows are NaN).

With ``identify_limbs`` (default) the node also learns the robot's four limb strengths from
consecutive requests: a request's ``stamp`` (the pose's capture time), pose, twist and firings
say where the robot went since the previous one, which the rollouts predict again with the
limbs as fired (:class:`frog_sim.core.limb_identification.LimbIdentification`, an extended
Kalman filter on the log-strengths). The trees are then rolled out with the estimate, which
``diagnostics`` reports per limb (``strength_FL`` ... and their sd); ``~/forget_limbs``
starts over (a new robot, a repaired limb). With ``yaw_torque_sd`` > 0 (default: the tank's
identified disturbance) the same filter estimates the tank's slowly varying yaw torque, and
the trees are rolled out with it decaying over ``yaw_torque_tau_s`` (``yaw_torque_Nm`` on
``diagnostics``); 0 assumes a calm tank.

    ros2 run frog_sim rollout_node --ros-args -p threads:=2
    ros2 service call /frog/rollouts soft_robot_interfaces/srv/Rollouts "{period: 1.43, depth: 1}"
"""

from __future__ import annotations

import math
import sys
import time

import numpy as np
from rclpy.node import Node
from soft_robot_common import MessageGate, Param, declare_parameters, run_node
from soft_robot_common.diagnostics import OK, WARN, NodeDiagnostics
from soft_robot_interfaces.srv import Rollouts as RolloutsSrv
from std_srvs.srv import Trigger

from frog_sim.core.limb_identification import LimbIdentification
from frog_sim.core.rollouts import COAST_TIME_STEP, KICK_WINDOW, ROLLOUT_FORCE_TOLERANCE, Rollouts
from frog_common.primitives import LIMB_NAMES, PRIMITIVE_NAMES
from frog_sim.core.simulation import DEFAULT_TIME_STEP
from frog_sim.core.yaw_disturbance import TANK_YAW_TORQUE_SD, TANK_YAW_TORQUE_TAU_S

MAX_DEPTH = 2

PARAMS = [
    Param("threads", 0, "threads the rollouts are spread over; 0 = the CPUs this process may use", min=0, max=64),
    Param("kick_time_step", DEFAULT_TIME_STEP, "time step during the kick window [s]", min=1e-4, max=0.01),
    Param("coast_time_step", COAST_TIME_STEP, "longest time step after the kick window [s]", min=1e-4, max=0.05),
    Param("kick_window", KICK_WINDOW, "fine steps for this long after each firing [s]", min=0.0, max=5.0),
    Param("force_tolerance", ROLLOUT_FORCE_TOLERANCE, "Newton residual tolerance [N]", min=1e-9, max=1e-2),
    Param("identify_limbs", True, "learn the robot's limb strengths from consecutive requests (stamp, pose, twist, "
          "firings) and roll out with them; false: the nominal limbs", live=True),
    Param("yaw_torque_sd", TANK_YAW_TORQUE_SD, "stationary sd of the tank's yaw torque [N m] the limb filter "
          "estimates alongside (with identify_limbs); 0 = assume none", min=0.0, max=1e-2, live=True),
    Param("yaw_torque_tau_s", TANK_YAW_TORQUE_TAU_S, "time constant of the tank's yaw torque [s]: the estimate "
          "decays with it through each rollout", min=0.05, max=60.0),
]


class RolloutNode(Node):
    """See the module docstring; parameters in ``PARAMS``."""

    NODE_NAME = "rollout_node"

    def __init__(self, **kwargs):
        super().__init__("rollout_node", **kwargs)
        self.cfg = declare_parameters(self, PARAMS, on_change=self.on_parameters)
        p = self.cfg
        self.gate = MessageGate(self)     # non-finite or oversized requests are refused
        t0 = time.monotonic()
        self.rollouts = Rollouts(threads=p["threads"] or None, kick_time_step=p["kick_time_step"],
                                 coast_time_step=max(p["coast_time_step"], p["kick_time_step"]),
                                 kick_window=p["kick_window"], force_tolerance=p["force_tolerance"],
                                 yaw_torque_tau=p["yaw_torque_tau_s"])
        # compile and warm up now, not in the first decision
        warm = self.rollouts.estimated_start((0.0, 0.0, 0.0), (0.01, 0.0, 0.0))
        self.rollouts.rollout_batch(warm, [("B",), ("C",)], period=0.5)
        self.identification = LimbIdentification(self.rollouts, torque_sd=p["yaw_torque_sd"])
        self.requests = self.failures = 0
        self.last_compute = math.nan
        self.create_service(RolloutsSrv, "frog/rollouts", self.on_request)
        self.create_service(Trigger, "~/forget_limbs", self.on_forget_limbs)
        self.diagnostics = NodeDiagnostics(self, "rollouts", self._diagnostics)
        self.get_logger().info(f"ready in {time.monotonic() - t0:.1f} s: {self.rollouts.threads} thread(s), "
                               f"step {p['kick_time_step'] * 1e3:.1f} ms for {p['kick_window']} s after a "
                               f"firing, then <= {p['coast_time_step'] * 1e3:.1f} ms; service "
                               f"{self.resolve_service_name('frog/rollouts')}")

    def _diagnostics(self):
        level = OK if not self.failures else WARN
        values = {"requests": self.requests, "failures": self.failures, "last_compute_s": self.last_compute,
                  "threads": self.rollouts.threads, "identify_limbs": self.cfg["identify_limbs"],
                  "identification_updates": self.identification.updates,
                  "yaw_torque_Nm": self.identification.torque,
                  "yaw_torque_sd_Nm": self.identification.torque_estimate_sd,
                  "ready": True}         # its diagnostics start once the rollouts are compiled and serve
        for limb, value in self.rollouts.limb_strength.items():
            values[f"strength_{limb}"] = value
            values[f"strength_sd_{limb}"] = self.identification.sd[limb]
        return level, "ready", values

    def on_parameters(self, changed: dict) -> None:
        if "identify_limbs" in changed or "yaw_torque_sd" in changed:
            self.forget_limbs()

    def forget_limbs(self) -> None:
        self.identification = LimbIdentification(self.rollouts, torque_sd=self.cfg["yaw_torque_sd"])
        self.rollouts.set_limb_strength(None)

    def on_forget_limbs(self, request, response):
        learned = self.identification.strengths
        self.forget_limbs()
        response.success = True
        response.message = "limbs back to nominal; were " + ", ".join(f"{k} {v:.3f}" for k, v in learned.items())
        self.get_logger().info(response.message)
        return response

    def _refuse(self, response, reason: str):
        self.failures += 1
        self.get_logger().error(f"rollouts refused: {reason}", throttle_duration_sec=1.0)
        response.success, response.message = False, reason
        return response

    def on_request(self, request, response):
        self.requests += 1
        problem = self.gate.problem(request, stamped=False)
        if problem:
            return self._refuse(response, problem)
        if not 1 <= request.depth <= MAX_DEPTH:
            return self._refuse(response, f"depth {request.depth} is out of range 1-{MAX_DEPTH}")
        if not (math.isfinite(request.period) and 0.0 < request.period <= 5.0):
            return self._refuse(response, f"period {request.period!r} s must be in (0, 5]")
        if len(request.fired_limbs) != len(request.fired_ago):
            return self._refuse(response, f"{len(request.fired_limbs)} fired_limbs but "
                                          f"{len(request.fired_ago)} fired_ago")
        fired = {}
        for limb, ago in zip(request.fired_limbs, request.fired_ago):
            if limb not in LIMB_NAMES:
                return self._refuse(response, f"fired_limbs: unknown limb {limb!r}; expected one of "
                                              f"{', '.join(LIMB_NAMES)}")
            if not (math.isfinite(ago) and ago >= 0.0):
                return self._refuse(response, f"fired_ago of {limb} = {ago!r} s must be finite and >= 0")
            fired[limb] = -float(ago)
        if not (math.isfinite(request.lead) and 0.0 <= request.lead <= 5.0):
            return self._refuse(response, f"lead {request.lead!r} s must be in [0, 5]")
        firsts = list(request.first_primitives)
        unknown = [n for n in firsts if n not in PRIMITIVE_NAMES]
        if unknown:
            return self._refuse(response, f"first_primitives: unknown {unknown}; expected some of "
                                          f"{', '.join(PRIMITIVE_NAMES)}")
        pose = (request.pose.x, request.pose.y, request.pose.theta)
        twist = (request.twist.linear.x, request.twist.linear.y, request.twist.angular.z)
        t0 = time.monotonic()
        stamp = request.stamp.sec + request.stamp.nanosec * 1e-9
        try:
            if self.cfg["identify_limbs"] and stamp > 0.0:
                start = self.identification.start(stamp, pose, twist, {k: stamp + t for k, t in fired.items()})
            else:
                start = self.rollouts.estimated_start(pose, twist, fired, now=0.0)
            rows, result = self.rollouts.decision_tree(start, request.period, request.depth, request.lead, firsts)
        except ValueError as exc:
            return self._refuse(response, str(exc))
        self.last_compute = time.monotonic() - t0
        if not np.all(result.converged):
            return self._refuse(response, f"{int(np.sum(~result.converged))} of {len(result.sequences)} rollouts "
                                          f"did not converge")
        response.success = True
        st = result.stats
        response.message = (f"{len(result.sequences)} sequences, {st['jobs']} jobs, {st['steps']} steps in "
                            f"{self.last_compute:.3f} s")
        response.primitive_names = list(PRIMITIVE_NAMES)
        response.transitions = rows.ravel().tolist()
        end = result.lead_end
        c, s = math.cos(pose[2]), math.sin(pose[2])
        dx, dy = end.pose[0] - pose[0], end.pose[1] - pose[1]
        response.lead_transition = [c * dx + s * dy, -s * dx + c * dy, end.pose[2] - pose[2], *map(float, end.twist)]
        response.compute_time = self.last_compute
        self.get_logger().debug(response.message)
        return response

    def destroy_node(self):
        self.rollouts.close()
        return super().destroy_node()


def main(args=None) -> int:
    return run_node(RolloutNode, args)


if __name__ == "__main__":
    sys.exit(main())
