"""ROS-facing parts of the twin (entry scripts start the nodes of the other packages as processes)."""
