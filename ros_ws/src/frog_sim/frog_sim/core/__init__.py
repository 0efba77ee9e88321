"""Pure-Python core of frog_sim: no rclpy imports, unit-tested without ROS."""
