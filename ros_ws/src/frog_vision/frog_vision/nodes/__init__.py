"""Thin ROS 2 node modules of frog_vision: parameters and messages in, core calls, messages out."""
