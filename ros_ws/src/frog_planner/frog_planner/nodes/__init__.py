"""Thin ROS 2 node modules of frog_planner: parameters and messages in, core calls, messages out."""
