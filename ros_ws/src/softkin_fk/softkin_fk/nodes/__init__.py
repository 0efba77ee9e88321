"""Thin ROS 2 node modules of softkin_fk: parameters and messages in, core calls, messages out."""
