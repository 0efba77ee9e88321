"""Thin ROS 2 node modules of frog_sim: parameters and messages in, core calls, messages out."""
