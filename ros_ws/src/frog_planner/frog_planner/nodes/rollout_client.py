"""planner_node's side of ``transitions: simulator``: asking ``frog/rollouts`` for a decision's tree.

What the robot can know goes into the request (DESIGN.md, "Planning modes"): the tracked
pose (with its stamp) and body twist, and how long ago each limb was fired, from what the
bridge wrote (``frog/bridge/sent``, LimbActivation stamped at the write). The request's ``lead`` coasts
that state from the pose's capture stamp to the moment the decision will be executed, so
the tree starts where the robot will be when it fires.
"""

from __future__ import annotations

import numpy as np
from geometry_msgs.msg import Pose2D, Twist

from frog_planner.core.tree_search import check_rows, reanchor_rows, tree_from_rows

#: A limb fired longer ago than this has relaxed (the actuation model's recovery is ~1-2 s).
FIRING_MEMORY_S = 10.0


class RolloutClient:
    """Requests of one planner: limb firing record, request building, response checking."""

    def __init__(self, node, service: str, limb_names: dict):
        from soft_robot_interfaces.srv import Rollouts
        self._Request = Rollouts.Request
        self.node = node
        self.client = node.create_client(Rollouts, service)
        self.limb_names = limb_names       # LimbActivation id -> name ("FL", ...)
        self.fired = {}                    # limb name -> node-clock Time of its last pulse start
        self.last_compute_s = float("nan")  # the server's compute time of the last response

    def on_sent(self, msg) -> None:
        """Record the limbs the bridge fired (``frog/bridge/sent``)."""
        from rclpy.time import Time
        stamp = Time.from_msg(msg.header.stamp, clock_type=self.node.get_clock().clock_type)
        for limb in msg.limbs:
            name = self.limb_names.get(int(limb))
            if name is not None and (name not in self.fired or stamp > self.fired[name]):
                self.fired[name] = stamp

    def request(self, pose, twist, at, period: float, depth: int, lead: float, first_primitives=()):
        """Send the request for a state valid at node-clock time ``at``; returns the future, or a reason."""
        if not self.client.service_is_ready():
            return None, f"rollout service {self.client.srv_name} is not available"
        req = self._Request(pose=Pose2D(x=float(pose[0]), y=float(pose[1]), theta=float(pose[2])),
                            period=float(period), depth=int(depth), lead=float(max(lead, 0.0)),
                            first_primitives=list(first_primitives))
        req.stamp = at.to_msg()            # the pose's: the server learns the limbs from consecutive ones
        t = Twist()
        t.linear.x, t.linear.y, t.angular.z = (float(v) for v in twist)
        req.twist = t
        for name, stamp in self.fired.items():
            ago = (at - stamp).nanoseconds * 1e-9
            if -0.05 <= ago < FIRING_MEMORY_S:           # a pulse stamped just after the pose: now
                req.fired_limbs.append(name)
                req.fired_ago.append(max(ago, 0.0))
        return self.client.call_async(req), None

    def cancel(self, future) -> None:
        if future is not None and not future.done():
            self.client.remove_pending_request(future)

    def result(self, future, reason, names, depth: int, reanchor: bool, deadline_periods: float, period: float):
        """At the deadline: ``(expander, None)`` from a response that came in time, else ``(None, why not)``
        (``reason``: why no request was sent). A request still pending is cancelled; the server's compute
        time of the last response is kept (``last_compute_s``)."""
        if future is None:
            return None, reason
        if not future.done():
            self.cancel(future)
            return None, (f"rollouts missed the deadline ({deadline_periods:.2f} periods = "
                          f"{deadline_periods * period:.2f} s)")
        try:
            response = future.result()
            self.last_compute_s = float(response.compute_time)
            return self.expander(response, names, depth, reanchor)
        except Exception as exc:           # noqa: BLE001 - a failed call is a fallback, not a crash
            return None, f"rollout call failed: {exc}"

    @staticmethod
    def expander(response, names, depth: int, reanchor: bool = False):
        """The search's expander from a successful response, or (None, reason).

        It chains the tree from the pose the search gives it: the request's pose, or with
        ``reanchor`` the pose tracked when the decision is executed (the response's
        ``lead_transition`` takes the lead out of level 1)."""
        if not response.success:
            return None, f"rollouts refused: {response.message}"
        if list(response.primitive_names) != list(names):
            return None, (f"the simulator's primitives {list(response.primitive_names)} are not the "
                          f"library's {list(names)}")
        values = np.asarray(response.transitions, dtype=float)
        try:
            if values.size % 6:
                raise ValueError(f"{values.size} transition values are not rows of 6")
            rows = values.reshape(-1, 6)
            check_rows(rows, depth, len(names))
        except ValueError as exc:
            return None, str(exc)
        if not np.any(np.all(np.isfinite(rows[-len(names) ** depth:]), axis=1)):
            return None, "the rollouts returned no finite leaf"
        if reanchor:
            try:
                rows = reanchor_rows(rows, response.lead_transition, len(names))
            except ValueError as exc:
                return None, str(exc)
        return (lambda pose, velocity, d: tree_from_rows(pose, rows, d, len(names))), None


