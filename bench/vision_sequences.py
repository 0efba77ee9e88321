"""Rendered test sequences of frog_sim's simulated frog (shared by bench/vision_accuracy.py
and tests/test_vision_accuracy.py; outside any package core, so it may use both cores).

The simulator executes a primitive every 1.5 s (forward and turning strokes); every
camera frame (30 fps) is rendered from the simulator's exact state: centre-of-mass pose,
body twist and rod network, with the tag on the body ring's centre (the pose is the ring
centre's, the twist that point's body-frame velocity). The limb firings of the simulator's
schedule come with it: the kick inputs that the bridge reports on ``frog/bridge/sent``.
"""
from __future__ import annotations

import numpy as np

from frog_vision.core.evaluation import SequenceResult, run_sequence
from frog_vision.core.pose import PoseSettings
from frog_vision.core.robot_shape import RobotShape, shape_from_segments
from frog_vision.core.synthetic import Trajectory

#: the sequences' pose is the body ring centre's (where the tag is): track it with no tag-to-body offset
RING_CENTRE_POSE = PoseSettings(offset_x=0.0, offset_y=0.0, offset_yaw=0.0)

#: a forward stroke (B: all four limbs), three turning strokes one way (E: the two left limbs),
#: a forward stroke and three the other way (F: the two right limbs); the turns are the
#: strongest of the simulated primitives (35 deg of heading over 10 s, up to 8 deg/s)
DEFAULT_PRIMITIVES = ("B", "E", "E", "E", "B", "F", "F", "F")


def simulated_sequence(duration=10.0, fps=30.0, primitives=DEFAULT_PRIMITIVES, period=1.5,
                       start=(-0.05, -0.15, 0.6)):
    """(Trajectory, list of body-frame RobotShape, kicks) of the simulated frog at the camera's
    times; kicks: sorted firing times [s] (one per pulse start: front limbs, then rear limbs)."""
    from frog_sim.core.model_parameters import FrogParameters
    from frog_sim.core.simulation import FrogSimulation
    sim = FrogSimulation(FrogParameters())
    sim.set_pose(*start)
    edges = sim.model.network.edges
    ts, poses, twists, shapes = [], [], [], []
    k, next_primitive = 0, 0.2
    for i in range(int(round(duration * fps))):
        t = i / fps
        while sim.time + 1e-9 < t:
            if sim.time + 1e-9 >= next_primitive:
                sim.execute_primitive(primitives[k % len(primitives)])
                k += 1
                next_primitive += period
            sim.step(1)
        s = sim.rigid_body_state()
        world = shape_from_segments(sim.node_positions[edges.ravel()].reshape(-1, 2, 2))
        # the tag's pose: the body ring's centre (the COM of eq. 10 includes the limbs' added
        # mass, a few mm aft of the ring centre with broad limbs)
        centre = np.asarray(world.ring_centre, dtype=float)
        pose = np.array([centre[0], centre[1], s.heading])
        r = centre - s.com
        v = s.com_velocity + s.yaw_rate * np.array([-r[1], r[0]])
        c, sn = np.cos(pose[2]), np.sin(pose[2])
        rot = np.array([[c, -sn], [sn, c]])
        shapes.append(RobotShape((world.ring - pose[:2]) @ rot, (world.limbs - pose[:2]) @ rot))
        ts.append(sim.time)
        poses.append(pose)
        twists.append([c * v[0] + sn * v[1], -sn * v[0] + c * v[1], s.yaw_rate])
    fired = np.concatenate([np.asarray(v, float) for v in sim.schedule.per_limb()])
    kicks = np.unique(np.round(fired[fired <= ts[-1]], 9))
    return Trajectory(np.array(ts), np.array(poses), np.array(twists), np.zeros(len(ts))), shapes, kicks


def run_simulated(renderer, tracker, truth: Trajectory, shapes, kicks=(), occlusion=()) -> SequenceResult:
    """Render and track a simulated sequence (like ``evaluation.run_sequence`` with the
    simulator's shapes; the tag sits on each frame's ring centre). Each kick [s] is given to
    the tracker before the first frame captured at or after it (as the node gets the bridge's
    message, which is written before the stroke shows in a frame); ``kicks=()``: no inputs."""
    return run_sequence(renderer, tracker, truth, occlusion, shapes=shapes, kicks=kicks, occluder_radius=0.07)
