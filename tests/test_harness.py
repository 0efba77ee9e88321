"""Self-test of the harness: a started node is found, stops cleanly, and leaves the graph."""

import os
import signal
import time

import pytest
import serial

pytestmark = pytest.mark.system


def test_started_node_is_found_and_gone_after_stop(launch, probe, tmp_path):
    t0 = time.monotonic()
    rec = launch("recorder", params={"output_dir": str(tmp_path / "rec"), "file_prefix": "h"})
    probe.wait_for_node("/recorder", timeout=20.0)
    assert rec.running()
    appeared = time.monotonic() - t0
    t1 = time.monotonic()
    code = rec.stop()
    stop_time = time.monotonic() - t1
    assert code == 0 and rec.stopped_cleanly, rec.log_text()
    probe.wait_node_gone("/recorder", timeout=10.0)
    gone = time.monotonic() - t1
    assert appeared < 20.0 and stop_time < 10.0 and gone < 10.0
    print(f"node appeared after {appeared:.2f} s, exited {stop_time:.2f} s after SIGINT, "
          f"left the graph after {gone:.2f} s")


def test_stop_escalates_when_sigint_is_ignored(launch, tmp_path):
    script = tmp_path / "stubborn.py"
    script.write_text("import signal, time\nsignal.signal(signal.SIGINT, signal.SIG_IGN)\n"
                      "print('up', flush=True)\ntime.sleep(60)\n")
    proc = launch("python3", str(script), name="stubborn")
    proc.wait_for_log("up")
    t = time.monotonic()
    proc.stop(sigint_timeout=0.5, sigterm_timeout=5.0)
    took = time.monotonic() - t
    assert not proc.running()
    assert proc.stop_signal == "SIGTERM" and not proc.stopped_cleanly
    assert took < 5.0
    report = proc.stop_report()      # what the twin's supervision summary keeps per node
    assert report["signal"] == "SIGTERM" and report["code"] == -signal.SIGTERM, report
    assert 0.5 <= report["seconds"] <= took + 0.01, (report, took)


def test_domains_are_isolated(ros_domain):
    from ros_harness import acquire_domain
    other = acquire_domain()
    try:
        assert other.domain_id != ros_domain.domain_id
        assert os.environ["ROS_DOMAIN_ID"] == str(ros_domain.domain_id)
        assert ros_domain.env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    finally:
        other.release()


def test_pty_pair_behaves_like_a_serial_port(serial_pair):
    controller, path = serial_pair
    with serial.Serial(path, 115200, timeout=1.0) as port:
        port.write(b"h 0 1\n")
        port.flush()
        got = b""
        deadline = time.monotonic() + 2.0
        while not got.endswith(b"\n") and time.monotonic() < deadline:
            got += os.read(controller, 64)
        assert got == b"h 0 1\n"
        os.write(controller, b"Cent,Q,1.0\n")
        assert port.readline() == b"Cent,Q,1.0\n"
