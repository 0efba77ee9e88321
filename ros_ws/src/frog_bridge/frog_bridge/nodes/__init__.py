"""Thin ROS 2 node modules of frog_bridge: parameters and messages in, core calls, messages out."""
