"""Main job (``./dev main``): the digital twin on the paper's line, sine and ellipse.

camera_sim -> tracker_node -> planner_node -> bridge_node -> pty -> robot_emulator ->
sim_node, each a process on the simulator's clock, plus recorder and image_preview; per path
a plot, a video, metrics and the MCAP recording in runs/main_<time>/, and a table beside the
real robot's figures. All options: ``python scripts/main_job.py --help`` (= ``frog-twin``).
"""

import sys

from frog_twin.twin import main

if __name__ == "__main__":
    sys.exit(main())
