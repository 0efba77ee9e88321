"""Library-backed receding-horizon path-following planner for the frog robot (seed 000, Algorithm
1).
"""
