"""Thin ROS 2 node modules of frog_logger: parameters and messages in, core calls, messages out."""
