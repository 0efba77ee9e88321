"""run_node's stops: a SIGINT while the node is constructed ends the process, also when the first
KeyboardInterrupt is raised inside a callback from C (which Python prints and drops, as
llvmlite's object-cache callback does while numba compiles a node's kernels); a callback or a
teardown that hangs leaves its traceback in the node's log."""

import signal
import subprocess
import sys
import textwrap
import time

import pytest

pytestmark = pytest.mark.system

SCRIPT = textwrap.dedent("""
    import ctypes, sys, time
    from rclpy.node import Node
    from soft_robot_common.node_main import run_node

    CALLBACK = ctypes.CFUNCTYPE(None)
    def busy():                       # Python run from C: an exception here is printed and dropped
        t = time.monotonic()
        while time.monotonic() - t < 0.05:
            pass
    call_from_c = CALLBACK(busy)

    class SlowStart(Node):
        def __init__(self):
            super().__init__("slow_start")
            print("constructing", flush=True)
            t = time.monotonic()
            while time.monotonic() - t < 30.0:   # mostly inside the callback, as a compile is in C
                call_from_c()
                sum(range(2000))

    sys.exit(run_node(SlowStart))
""")


def test_sigint_during_a_start_up_that_swallows_exceptions_still_stops_it():
    proc = subprocess.Popen([sys.executable, "-c", SCRIPT], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    try:
        assert proc.stdout.readline().strip() == "constructing"
        time.sleep(0.5)
        t0 = time.monotonic()
        proc.send_signal(signal.SIGINT)
        code = proc.wait(timeout=10)
        took = time.monotonic() - t0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    err = proc.stderr.read()
    assert code == 0, err
    assert "stopped by signal during start-up" in err
    assert took < 5.0, f"stopped {took:.1f} s after SIGINT"


READY_NODE = textwrap.dedent("""
    import sys, time
    from rclpy.node import Node
    from soft_robot_common import node_main

    class Ready(Node):
        \"\"\"Prints "ready" once it spins (its start-up is over).\"\"\"
        def __init__(self):
            super().__init__("ready_node")
            self.said = False
            self.create_timer(0.05, self.tick)

        def tick(self):
            if not self.said:
                print("ready", flush=True)
                self.said = True
""")

HUNG_TEARDOWN = READY_NODE + textwrap.dedent("""
    node_main.STUCK_DUMP_S = 0.5

    def close_that_hangs(node):
        time.sleep(1.5)

    sys.exit(node_main.run_node(Ready, close=close_that_hangs))
""")


def _stop_when_ready(script: str, wait_s: float = 0.0) -> tuple[int, str]:
    """Run ``script``, SIGINT it ``wait_s`` after it printed "ready"; its exit code and stderr."""
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    try:
        assert proc.stdout.readline().strip() == "ready"
        time.sleep(wait_s)
        proc.send_signal(signal.SIGINT)
        code = proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return code, proc.stderr.read()


def test_a_teardown_that_hangs_dumps_its_traceback_and_a_quick_one_does_not():
    code, err = _stop_when_ready(HUNG_TEARDOWN)
    assert code == 0, err      # slow, not dead: the stop still completes
    assert "close_that_hangs" in err and "Thread" in err, err
    code, err = _stop_when_ready(HUNG_TEARDOWN.replace("time.sleep(1.5)", "pass"))
    assert code == 0 and "close_that_hangs" not in err, err


STUCK_CALLBACK = textwrap.dedent("""
    import sys, time
    from rclpy.node import Node
    from soft_robot_common import node_main

    node_main.STUCK_DUMP_S = 1.5
    class Stuck(Node):
        def __init__(self):
            super().__init__("stuck_callback")
            self.n = 0
            self.create_timer(0.05, self.tick)

        def tick(self):
            self.n += 1
            if self.n == 3:
                print("ready", flush=True)
            if self.n == 5:
                callback_that_blocks()

    def callback_that_blocks():
        time.sleep(4.0)

    sys.exit(node_main.run_node(Stuck))
""")


def test_a_callback_that_blocks_the_spin_loop_dumps_its_traceback():
    code, err = _stop_when_ready(STUCK_CALLBACK, wait_s=4.5)      # the blocking callback ran and returned
    assert code == 0, err
    assert err.count("callback_that_blocks") == 1, err     # dumped once, while it blocked
    assert err.count("Timeout (") == 1, err                 # and never while the loop was turning


BLOCKED_MIDDLEWARE = READY_NODE + textwrap.dedent("""
    node_main.MIDDLEWARE_TEARDOWN_S = 1.0
    class Blocked(Ready):
        def destroy_node(self):          # as Fast DDS deleting a writer with a dead reliable reader
            time.sleep(60)

    def close(node):
        print("closed", file=sys.stderr, flush=True)

    sys.exit(node_main.run_node(Blocked, close=close))
""")


def test_a_blocked_middleware_teardown_ends_the_process_after_its_limit_and_says_where():
    t0 = time.monotonic()
    code, err = _stop_when_ready(BLOCKED_MIDDLEWARE)
    took = time.monotonic() - t0
    assert code == 0, err
    assert took < 5.0, took                     # not the 60 s of the blocked call
    assert "teardown (destroy_node, rclpy.shutdown) is still blocked after 1 s" in err, err
    assert "in destroy_node" in err, err        # the traceback of where it was blocked
    assert err.index("closed") < err.index("still blocked"), err    # the node's own close() ran first
