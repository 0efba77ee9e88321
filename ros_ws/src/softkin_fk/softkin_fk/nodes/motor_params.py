"""The finger's motors and board, as both ends of the serial line declare them.

``stepper_driver`` (the host) and ``marlin_emulator`` (the board it talks to) must agree on
the cable-to-axis map and the step geometry; one definition serves both.
"""
from __future__ import annotations

from soft_robot_common import Param

#: the emulator's device link and the driver's default port (per namespace: namespaced_path)
DEFAULT_PORT_LINK = "/tmp/softkin_marlin"

MOTOR_PARAMS = [
    Param("joints", ["cable_0", "cable_1", "cable_2"], "cable (joint) names of the setpoints, one per axis"),
    Param("axes", ["X", "Y", "Z"], "Marlin axis letter of each cable"),
    Param("pulley_radius", 0.005, "radius the cables wind on [m]", min=1e-4, max=0.1),
    Param("steps_per_rev", 200, "full steps per motor revolution (1.8 deg motors: 200)", min=1, max=10000),
    Param("microsteps", 16, "driver microstepping (RAMPS A4988, all jumpers: 16)", min=1, max=256),
    Param("steps_per_unit", 80.0, "the board's microsteps per axis unit (its M92 setting)", min=1e-3, max=5000.0),
]
