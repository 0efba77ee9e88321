"""Pure-Python core of frog_logger: no rclpy imports, unit-tested without ROS."""
