"""Geometric forward and inverse kinematics of soft robots on tetrahedral and prism meshes (seed
001), with cable, DEA and pneumatic actuation.
"""
