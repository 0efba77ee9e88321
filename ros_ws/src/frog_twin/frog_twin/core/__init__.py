"""rclpy-free composition code: joins frog_sim's simulator with frog_planner's planner (the one package allowed to)."""
