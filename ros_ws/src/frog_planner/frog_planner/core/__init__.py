"""Pure-Python core of frog_planner: no rclpy imports, unit-tested without ROS."""
