"""Pure-Python core of frog_bridge (no rclpy): protocol codec, scheduler, limb protection,
link supervision, and the robot emulator's model."""
