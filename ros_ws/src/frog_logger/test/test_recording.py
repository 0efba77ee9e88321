"""Recording: split files, never overwrite (a restart continues the numbering), write errors, recovery."""

import errno

import pytest
from mcap.reader import make_reader

from frog_logger.core import recording as recording_module
from frog_logger.core.log_files import LogFileError, check, recover, summarize
from frog_logger.core.recording import Recording, RecordingError, check_output_folder

DEF = "float64 x\n"


def _payload(i: int) -> bytes:
    # CDR of a message with one float64: 4-byte encapsulation header + 8 bytes
    import struct
    return b"\x00\x01\x00\x00" + struct.pack("<d", float(i))


def _messages(path):
    with open(path, "rb") as f:
        return [(c.topic, m.log_time, m.data) for _, c, m in make_reader(f).iter_messages()]


def test_split_by_size_keeps_all_messages_in_order(tmp_path):
    rec = Recording(tmp_path, "s", max_file_bytes=2000, compression="none")
    rec.add_topic("/a", "pkg/msg/X", DEF)
    rec.add_topic("/b", "pkg/msg/X", DEF)
    for i in range(300):
        assert rec.write("/a" if i % 3 else "/b", _payload(i), 1_000 + i)
        if i % 20 == 0:
            rec.flush()
    rec.close()
    assert len(rec.files) > 3
    got = []
    for f in rec.files:
        assert summarize(f).complete
        got += _messages(f)
    assert [m[2] for m in got] == [_payload(i) for i in range(300)]
    assert [m[1] for m in got] == [1_000 + i for i in range(300)]
    assert check(rec.files[-1]).ok


def test_split_by_duration(tmp_path):
    rec = Recording(tmp_path, "d", max_file_duration_s=1.0)
    rec.add_topic("/a", "pkg/msg/X", DEF)
    for i in range(50):
        rec.write("/a", _payload(i), int(i * 0.1e9))  # 5 s of data
    rec.close()
    assert len(rec.files) == 5


def test_a_restart_continues_after_the_existing_files_and_never_touches_them(tmp_path):
    (tmp_path / "r_000.mcap").write_bytes(b"precious")
    (tmp_path / "r_002.mcap").write_bytes(b"also precious")       # numbering continues after the highest
    (tmp_path / "r_x.mcap").write_bytes(b"other")                   # not one of the recording's files
    (tmp_path / "rr_007.mcap").write_bytes(b"another prefix")
    rec = Recording(tmp_path, "r", max_file_bytes=2000, compression="none")
    assert [p.name for p in rec.existing_files] == ["r_000.mcap", "r_002.mcap"]
    assert rec.current_file.name == "r_003.mcap"
    rec.add_topic("/a", "pkg/msg/X", DEF)
    (tmp_path / "r_004.mcap").write_bytes(b"made meanwhile")         # by another process: skipped, not truncated
    for i in range(100):
        rec.write("/a", _payload(i), i)
        if i % 10 == 0:
            rec.flush()                     # a closed chunk counts in the file size
    rec.close()
    assert [p.name for p in rec.files][:2] == ["r_003.mcap", "r_005.mcap"] and len(rec.files) > 2
    assert [m[2] for f in rec.files for m in _messages(f)] == [_payload(i) for i in range(100)]
    for name, data in (("r_000.mcap", b"precious"), ("r_002.mcap", b"also precious"), ("r_x.mcap", b"other"),
                       ("rr_007.mcap", b"another prefix"), ("r_004.mcap", b"made meanwhile")):
        assert (tmp_path / name).read_bytes() == data


def test_unusable_folders(tmp_path):
    f = tmp_path / "file"
    f.write_text("x")
    with pytest.raises(RecordingError, match="cannot be created"):
        check_output_folder(f / "sub")


def test_disk_full_drops_counts_and_recovers_into_new_file(tmp_path, monkeypatch):
    rec = Recording(tmp_path, "f", compression="none")
    rec.add_topic("/a", "pkg/msg/X", DEF)
    for i in range(10):
        rec.write("/a", _payload(i), i)
    assert rec.flush()
    real_flush = recording_module.Writer.flush

    def full(self):
        raise OSError(errno.ENOSPC, "No space left on device")
    monkeypatch.setattr(recording_module.Writer, "flush", full)
    rec.write("/a", _payload(10), 10)
    assert not rec.flush()
    assert "disk full" in rec.error
    assert not rec.write("/a", _payload(11), 11)
    assert rec.dropped_messages == 1 and rec.current_file is None
    monkeypatch.setattr(recording_module.Writer, "flush", real_flush)
    assert rec.retry() and rec.error is None
    rec.write("/a", _payload(12), 12)
    rec.close()
    assert rec.files[1].name == "f_001.mcap"
    assert [m[2] for m in _messages(rec.files[1])] == [_payload(12)]
    # the broken first file still gives back what was flushed before the failure
    n, clean = recover(rec.files[0], tmp_path / "fixed.mcap")
    assert not clean and [m[2] for m in _messages(tmp_path / "fixed.mcap")][:10] == \
        [_payload(i) for i in range(10)]


@pytest.mark.parametrize("cut", [0.3, 0.6, 0.95])
def test_recover_truncated_file_gives_gap_free_prefix(tmp_path, cut):
    rec = Recording(tmp_path, "t")
    rec.add_topic("/a", "pkg/msg/X", DEF)
    for i in range(1000):
        rec.write("/a", _payload(i), i)
        if i % 100 == 99:
            rec.flush()
    rec.close()
    data = rec.files[0].read_bytes()
    broken = tmp_path / "broken.mcap"
    broken.write_bytes(data[: int(len(data) * cut)])
    assert not summarize(broken).complete
    with pytest.raises(LogFileError, match="recover"):
        list(__import__("frog_logger.core.log_files", fromlist=["x"]).read_messages(broken))
    n, clean = recover(broken, tmp_path / "ok.mcap")
    got = [m[2] for m in _messages(tmp_path / "ok.mcap")]
    assert not clean and n == len(got) and got == [_payload(i) for i in range(n)]
    assert n % 100 == 0  # whole flushed chunks only


def test_not_mcap(tmp_path):
    p = tmp_path / "x.mcap"
    p.write_bytes(b"hello world")
    with pytest.raises(LogFileError, match="not an MCAP file"):
        summarize(p)
