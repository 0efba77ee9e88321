"""Rosbag-free recorder node writing raw CDR messages to MCAP, and the frog-log tool (info, export,
check, recover).
"""
