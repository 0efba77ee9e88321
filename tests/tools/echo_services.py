"""Test service process: serves SolveIk and ForwardKinematics with answers derived from the
request, so a test can check every field crossed the wire both ways.

SolveIk: actuation = reversed initial_guess, reached = target, residual_error = tolerance,
iterations = max_iterations + 1, success = True, message = "echo".
ForwardKinematics: marker_points[i] = (a_i, 2 a_i, -a_i), tip = last point, success = True.
"""

import sys

from geometry_msgs.msg import Point
from rclpy.node import Node
from soft_robot_common.node_main import run_node
from soft_robot_interfaces.srv import ForwardKinematics, SolveIk


def solve_ik(req, res):
    res.success = True
    res.actuation = list(reversed(req.initial_guess))
    res.reached = req.target
    res.residual_error = req.tolerance
    res.iterations = req.max_iterations + 1
    res.message = "echo"
    return res


def forward(req, res):
    res.marker_points = [Point(x=a, y=2 * a, z=-a) for a in req.actuation]
    res.tip = res.marker_points[-1] if res.marker_points else Point()
    res.success = True
    res.message = f"{len(req.actuation)} values"
    return res


class EchoServices(Node):
    NODE_NAME = "echo_services"

    def __init__(self):
        super().__init__("echo_services")
        self.create_service(SolveIk, "/test/solve_ik", solve_ik)
        self.create_service(ForwardKinematics, "/test/forward_kinematics", forward)


def main():
    sys.exit(run_node(EchoServices))  # its SIGINT handling: a clean stop exits 0


if __name__ == "__main__":
    main()
