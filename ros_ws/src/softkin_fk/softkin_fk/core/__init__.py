"""Pure-Python core of softkin_fk: no rclpy imports, unit-tested without ROS."""
