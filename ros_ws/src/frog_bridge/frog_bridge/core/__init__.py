"""Pure-Python core of frog_bridge: no rclpy imports, unit-tested without ROS."""
