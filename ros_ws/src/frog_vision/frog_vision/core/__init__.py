"""Pure-Python core of frog_vision: no rclpy imports, unit-tested without ROS."""
