"""The recorder as a real process: completeness at 1 kHz, crash survival, splitting, bad input."""

import csv
import math
import resource
import sys
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

sys.path.insert(0, str(Path(__file__).parent / "tools"))
from odom_content import odom_fields, read_field  # noqa: E402

from frog_logger.core.log_files import recover, summarize  # noqa: E402

pytestmark = pytest.mark.system


def _decoded(path, topic="/odom"):
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        return [(m.log_time, d) for _, _, m, d in reader.iter_decoded_messages(topics=[topic])]


def _wait_recorded(probe, count, timeout=60.0):
    """Wait until the recorder's diagnostics count ``count`` messages: it may still be taking
    a loaded machine's queue after the publisher is done, and a stop before that loses them.
    A recorder that lost some never gets there: then the file's own count is the failure."""
    from diagnostic_msgs.msg import DiagnosticArray

    def enough(msg):
        return any(kv.key == "messages" and int(kv.value) >= count
                   for st in msg.status if st.name.startswith("recorder") for kv in st.values)
    try:
        probe.wait_heard(DiagnosticArray, "/diagnostics", timeout=timeout, accept=enough)
    except TimeoutError:
        pass


def _assert_content(decoded_msg, seq):
    for key, want in odom_fields(seq).items():
        got = read_field(decoded_msg, key)
        if isinstance(want, list):
            assert list(got) == pytest.approx(want, abs=0), key
        else:
            assert got == want, (key, got, want)


def test_records_every_message_at_1khz_for_10s(launch, probe, tmp_path):
    out = tmp_path / "rec"
    rec = launch("recorder", params={"output_dir": str(out), "file_prefix": "odom",
                                     "topics": ["/odom"]})
    probe.wait_for_node("/recorder", timeout=20)
    pub = launch("odom_publisher.py", "--rate", "1000", "--count", "10000")
    pub.wait_for_log(r"done 10000 messages", timeout=60)
    _wait_recorded(probe, 10000)
    assert rec.stop() == 0 and rec.stopped_cleanly, rec.log_text()[-2000:]

    files = sorted(out.glob("odom_*.mcap"))
    assert [f.name for f in files] == ["odom_000.mcap"]
    msgs = _decoded(files[0])
    seqs = [int(d.pose.pose.position.x) for _, d in msgs]
    assert len(msgs) == 10000, f"{10000 - len(msgs)} messages lost"
    assert seqs == list(range(10000)), "messages out of order or duplicated"
    for seq in (0, 1, 4999, 9999):
        _assert_content(msgs[seq][1], seq)
    # full content check on a stride so the test stays fast
    for seq in range(0, 10000, 97):
        _assert_content(msgs[seq][1], seq)
    # receive timestamps are monotonic and span the publishing period
    times = [t for t, _ in msgs]
    assert all(b >= a for a, b in zip(times, times[1:]))
    assert 9.0 < (times[-1] - times[0]) / 1e9 < 12.0

    # the file carries its metadata: start time, host, topic list with type and QoS
    info = summarize(files[0])
    assert info.complete
    assert {"start_time_ns", "host"} <= set(info.metadata["recording"])
    topics = info.metadata["topics"]
    assert "nav_msgs/msg/Odometry" in topics["/odom"]
    assert "reliable" in topics["/odom"]


def test_sigkill_loses_at_most_the_last_second(launch, probe, tmp_path):
    out = tmp_path / "rec"
    rec = launch("recorder", params={"output_dir": str(out), "file_prefix": "crash",
                                     "topics": ["/odom"], "flush_period_s": 0.5})
    probe.wait_for_node("/recorder", timeout=20)
    pub = launch("odom_publisher.py", "--rate", "200", "--count", "0")
    pub.wait_for_log("publishing", timeout=30)
    time.sleep(4.0)
    kill_ns = time.time_ns()
    rec.send(9)  # SIGKILL: no chance to finish the file
    rec.wait(10)
    pub.stop()

    crashed = out / "crash_000.mcap"
    assert not summarize(crashed).complete
    fixed = tmp_path / "fixed.mcap"
    n, clean = recover(crashed, fixed)
    assert not clean and n > 0
    msgs = _decoded(fixed)
    seqs = [int(d.pose.pose.position.x) for _, d in msgs]
    assert seqs == list(range(len(seqs))), "recovered messages must be a gap-free prefix"
    last_stamp = msgs[-1][1].header.stamp
    last_ns = last_stamp.sec * 10**9 + last_stamp.nanosec
    lost_s = (kill_ns - last_ns) / 1e9
    print(f"recovered {n} messages; lost the last {lost_s:.2f} s before SIGKILL")
    assert lost_s <= 1.0, f"lost {lost_s:.2f} s of data"
    for seq in range(0, len(msgs), 53):
        _assert_content(msgs[seq][1], seq)


def test_a_restart_after_sigkill_starts_the_next_file_and_leaves_the_first_unchanged(launch, probe, tmp_path):
    """A recorder killed and started again with the same output_dir and file_prefix (as a supervisor does):
    crash_000.mcap stays byte for byte as the kill left it (recoverable), crash_001.mcap holds what came after."""
    import hashlib
    from diagnostic_msgs.msg import DiagnosticArray
    out = tmp_path / "rec"
    params = {"output_dir": str(out), "file_prefix": "crash", "topics": ["/odom"], "flush_period_s": 0.2}
    diags = []
    probe.node.create_subscription(DiagnosticArray, "/diagnostics", diags.append, 50)

    def recorded(file_name):
        """Messages the recorder writing ``file_name`` reports (its diagnostics), 0 before any."""
        counts = [int(v["messages"]) for d in diags for s in d.status if s.name == "recorder: recording"
                  for v in [{kv.key: kv.value for kv in s.values}] if v["file"].endswith(file_name)]
        return counts[-1] if counts else 0

    rec = launch("recorder", params=params, name="recorder_first")
    probe.wait_for_node("/recorder", timeout=20)
    pub = launch("odom_publisher.py", "--rate", "200", "--count", "0")
    pub.wait_for_log("publishing", timeout=30)
    probe.spin_until(lambda: recorded("crash_000.mcap") >= 200, 30, "200 messages in the first file")
    rec.send(9)                                      # SIGKILL: the file is left unfinished
    assert rec.wait(10) == -9
    first = out / "crash_000.mcap"
    digest = hashlib.sha256(first.read_bytes()).hexdigest()

    again = launch("recorder", params=params, name="recorder_again")
    again.wait_for_log(r"to \S*crash_001\.mcap \(after 1 earlier file\(s\) of this prefix, left untouched", timeout=30)
    probe.spin_until(lambda: recorded("crash_001.mcap") >= 200, 30, "200 messages in the second file")
    pub.stop()
    assert again.stop() == 0 and again.stopped_cleanly

    assert sorted(f.name for f in out.glob("*.mcap")) == ["crash_000.mcap", "crash_001.mcap"]
    assert hashlib.sha256(first.read_bytes()).hexdigest() == digest, "the first file was changed"
    n, clean = recover(first, tmp_path / "first_recovered.mcap")
    before = [int(d.pose.pose.position.x) for _, d in _decoded(tmp_path / "first_recovered.mcap")]
    assert not clean and n == len(before) > 0 and before == list(range(len(before)))
    assert summarize(out / "crash_001.mcap").complete
    after = [int(d.pose.pose.position.x) for _, d in _decoded(out / "crash_001.mcap")]
    assert len(after) >= 200 and after == list(range(after[0], after[0] + len(after)))
    assert after[0] > before[-1], "the second file continues after the first (only the time it was down lost)"


def test_split_by_duration_keeps_every_message_once(launch, probe, tmp_path):
    out = tmp_path / "rec"
    rec = launch("recorder", params={"output_dir": str(out), "file_prefix": "split",
                                     "topics": ["/odom"], "max_file_duration_s": 1.0})
    probe.wait_for_node("/recorder", timeout=20)
    pub = launch("odom_publisher.py", "--rate", "500", "--count", "1750")
    pub.wait_for_log("done 1750", timeout=60)
    _wait_recorded(probe, 1750)
    assert rec.stop() == 0
    files = sorted(out.glob("split_*.mcap"))
    assert len(files) >= 3
    seqs = []
    for f in files:
        assert summarize(f).complete
        seqs += [int(d.pose.pose.position.x) for _, d in _decoded(f)]
    assert seqs == list(range(1750))


def test_export_csv_round_trip(launch, probe, tmp_path):
    out = tmp_path / "rec"
    rec = launch("recorder", params={"output_dir": str(out), "file_prefix": "x",
                                     "topics": ["/odom"]})
    probe.wait_for_node("/recorder", timeout=20)
    launch("odom_publisher.py", "--rate", "100", "--count", "50").wait_for_log("done", 30)
    _wait_recorded(probe, 50)
    rec.stop()
    cli = launch("frog-log", "export", str(out / "x_000.mcap"), "-o", str(tmp_path / "csv"))
    assert cli.wait(60) == 0, cli.log_text()
    with open(tmp_path / "csv" / "odom.csv") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 50
    for seq, row in enumerate(rows):
        for key, want in odom_fields(seq).items():
            if isinstance(want, list):
                assert [float(row[f"{key}[{i}]"]) for i in range(36)] == want
            elif isinstance(want, float):
                assert float(row[key]) == want, key   # repr() round-trips floats exactly
            else:
                assert row[key] == want
    check = launch("frog-log", "check", str(out / "x_000.mcap"))
    assert check.wait(60) == 0 and "50 messages decoded" in check.log_text()


def test_unwritable_output_folder_exits_nonzero_with_message(launch, tmp_path):
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    rec = launch("recorder", params={"output_dir": str(blocker / "sub")})
    assert rec.wait(30) == 2
    assert "output folder" in rec.log_text() and "cannot be created" in rec.log_text()
    assert not list(tmp_path.rglob("*.mcap"))


def test_unknown_type_is_reported_and_other_topics_still_recorded(launch, probe, tmp_path):
    import os
    from soft_robot_interfaces.msg import Primitive
    # The recorder runs without our interface package on its paths: the type is unknown.
    env = {k: ":".join(p for p in os.environ.get(k, "").split(":")
                       if "soft_robot_interfaces" not in p)
           for k in ("AMENT_PREFIX_PATH", "PYTHONPATH", "LD_LIBRARY_PATH")}
    out = tmp_path / "rec"
    rec = launch("recorder", params={"output_dir": str(out), "file_prefix": "u"}, env=env)
    probe.wait_for_node("/recorder", timeout=20)
    prim_pub = probe.node.create_publisher(Primitive, "/frog/primitive", 10)
    rec.wait_for_log(r"not recording /frog/primitive: unknown message type "
                     r"'soft_robot_interfaces/msg/Primitive'", timeout=20)
    pub = launch("odom_publisher.py", "--rate", "100", "--count", "100")
    pub.wait_for_log("done 100", timeout=30)
    prim_pub.publish(Primitive(id=1, name="B"))
    time.sleep(0.5)
    assert rec.running(), "recorder must stay up after an unknown type"
    assert rec.stop() == 0
    msgs = _decoded(out / "u_000.mcap")
    assert len(msgs) == 100


def _limit_file_size():
    # Python ignores SIGXFSZ, so writes past the limit fail with EFBIG, like a full disk.
    resource.setrlimit(resource.RLIMIT_FSIZE, (200_000, 200_000))


def test_disk_full_is_logged_node_stays_up_and_data_is_salvageable(launch, probe, tmp_path):
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
    out = tmp_path / "rec"
    rec = launch("recorder", params={"output_dir": str(out), "file_prefix": "full",
                                     "topics": ["/odom"], "compression": "none",
                                     "retry_period_s": 3.0, "flush_period_s": 0.1},  # small chunks: several fit
                 preexec_fn=_limit_file_size)
    probe.wait_for_node("/recorder", timeout=20)
    diags = []
    probe.node.create_subscription(DiagnosticArray, "/diagnostics", diags.append, 10)
    pub = launch("odom_publisher.py", "--rate", "500", "--count", "1500")
    rec.wait_for_log(r"writing .* failed: file too large", timeout=30)
    pub.wait_for_log("done 1500", timeout=30)
    probe.spin_until(lambda: any(s.level == DiagnosticStatus.ERROR
                                 for d in diags for s in d.status), 10, "ERROR diagnostics")
    assert rec.running() and probe.node.count_publishers("/diagnostics") >= 1
    assert rec.stop() == 0
    n, _ = recover(out / "full_000.mcap", tmp_path / "salvaged.mcap")
    salvaged = _decoded(tmp_path / "salvaged.mcap")
    assert n == len(salvaged) > 50
    seqs = [int(d.pose.pose.position.x) for _, d in salvaged]
    assert seqs == list(range(len(seqs)))
    assert math.isclose(salvaged[-1][1].twist.twist.linear.x, 1e-3 * seqs[-1])
