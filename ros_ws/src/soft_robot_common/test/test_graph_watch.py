"""GraphWatch: its waits end when the graph shows what was asked, or say what did not happen."""

import subprocess
import sys

import pytest

from soft_robot_common.graph_watch import GraphWatch
from soft_robot_common.processes import acquire_domain

pytestmark = pytest.mark.system


class _Dead:
    name = "tracker_node"

    def running(self):
        return False

    def log_text(self):
        return "[FATAL] tag family not found"


@pytest.fixture
def watch():
    domain = acquire_domain()
    w = GraphWatch(domain, "watch_under_test")
    yield w, domain
    w.close()
    domain.release()


def test_waits_see_another_process_node_and_time_out_with_what(watch):
    w, domain = watch
    # a node in another process on the same domain (and on no other)
    code = ("import rclpy, time; rclpy.init(); n = rclpy.create_node('other'); "
            "n.create_publisher(__import__('std_msgs.msg', fromlist=['Empty']).Empty, '/seen', 10); "
            "time.sleep(60)")
    proc = subprocess.Popen([sys.executable, "-c", code], env=domain.env)
    try:
        assert w.wait_for_node("/other", timeout=60) < 60
        assert w.wait_for_topic("/seen", timeout=30) < 30
        with pytest.raises(TimeoutError, match="a subscriber on /seen not reached within 0.3 s"):
            w.wait_for_subscriber("/seen", timeout=0.3)
    finally:
        proc.kill()
        proc.wait()
    assert w.wait_node_gone("/other", timeout=60) < 60


def test_a_process_that_died_is_named_with_its_log(watch):
    w, _ = watch
    with pytest.raises(RuntimeError, match="tracker_node exited early:\n.*tag family"):
        w.spin_until(lambda: False, 5, "odometry", procs=[_Dead()])
