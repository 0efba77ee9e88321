"""The frog's shared vocabulary (pure Python, no ROS): every package's cores may import it."""
