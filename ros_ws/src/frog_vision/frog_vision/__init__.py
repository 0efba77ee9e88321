"""AprilTag tracking of the frog robot from an overhead camera: camera model, detection, pose and
velocity estimation.
"""
