"""run_node's start-up stop: a SIGINT while the node is constructed ends the process, also when
the first KeyboardInterrupt is raised inside a callback from C (which Python prints and drops,
as llvmlite's object-cache callback does while numba compiles a node's kernels)."""

import signal
import subprocess
import sys
import textwrap
import time

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
