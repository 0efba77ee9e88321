"""scripts/suite_under_load.py: its busy processes load the CPU, its runs report exit code and CPU
time as the kernel counts them, and it reads pytest's result line in both output styles."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "scripts"))
import suite_under_load as sul  # noqa: E402


def _cpu_seconds(pid):
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / 100.0       # utime + stime, clock ticks (USER_HZ 100)


@pytest.mark.system
def test_busy_processes_spin_and_are_stopped():
    busy = sul.start_busy(2)
    try:
        # each spins: its CPU time reaches 0.5 s, however loaded the machine (deadline, not a fixed wait)
        end = time.monotonic() + 60
        while min(spent := [_cpu_seconds(p.pid) for p in busy]) < 0.5 and time.monotonic() < end:
            time.sleep(0.05)
    finally:
        sul.stop_busy(busy)
    assert min(spent) >= 0.5, spent
    assert all(p.poll() is not None for p in busy)


@pytest.mark.system
def test_run_once_reports_exit_code_wall_and_cpu_time(tmp_path):
    log = tmp_path / "run.log"
    code, wall, cpu = sul.run_once([sys.executable, "-c",
                                    "import time\nt = time.process_time()\n"
                                    "while time.process_time() - t < 0.5: pass\nprint('x')\nraise SystemExit(3)"], log)
    assert code == 3
    assert 0.45 < cpu < wall + 0.1, (cpu, wall)      # the child's own CPU, counted by wait4
    assert log.read_text() == "x\n"


def test_result_line_of_both_pytest_styles(tmp_path):
    log = tmp_path / "run.log"
    log.write_text("collected 3 items\n...\n"
                   "========= 1 failed, 779 passed, 2 skipped in 1751.23s (0:29:11) =========\n")
    assert sul.result_line(log) == "1 failed, 779 passed, 2 skipped in 1751.23s (0:29:11)"
    log.write_text("...\n5 passed in 3.21s\n")
    assert sul.result_line(log) == "5 passed in 3.21s"
    log.write_text("ImportError: no module named x\n")
    assert sul.result_line(log) == ""


def _children(pid):
    """Pids of the processes whose parent is ``pid``, with their command lines."""
    out = {}
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                if int((d / "stat").read_text().rsplit(")", 1)[1].split()[1]) == pid:
                    out[int(d.name)] = (d / "cmdline").read_bytes().replace(b"\0", b" ").decode()
            except (OSError, ValueError, IndexError):
                pass
    return out


def _ignore_sigint():
    signal.signal(signal.SIGINT, signal.SIG_IGN)


@pytest.mark.parametrize("case", ["plain", "started-with-SIGINT-ignored", "a-test-ignoring-SIGINT"])
@pytest.mark.system
def test_sigterm_stops_the_run_and_the_busy_processes(tmp_path, case):
    """``kill`` (SIGTERM) of the driver mid-run: the run under way is stopped (pytest too, under
    ./dev's shell), the busy process does not spin on, and the summary is still written. Also when
    the driver was started with SIGINT ignored (``nohup ... &`` in a script: inherited by every
    child, so without care a series' pytest runs on after the stop), and when the run
    itself ignores SIGINT (then SIGTERM after the grace)."""
    slow = tmp_path / "test_slow.py"
    head = "import signal\nsignal.signal(signal.SIGINT, signal.SIG_IGN)\n" if case == "a-test-ignoring-SIGINT" else ""
    slow.write_text(head + "import time\n\ndef test_slow():\n    time.sleep(300)\n")
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, str(REPO / "scripts" / "suite_under_load.py"), "--runs", "1",
                             "--busy", "1", "--out", str(out), "--", "-n", "0", "-p", "no:cacheprovider", str(slow)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=_ignore_sigint if case == "started-with-SIGINT-ignored" else None)
    try:
        end = time.monotonic() + 120
        busy = {}
        while time.monotonic() < end and not (busy and (out / "run_1.log").exists()
                                              and "test_slow.py" in (out / "run_1.log").read_text()):
            busy = {p: c for p, c in _children(proc.pid).items() if sul.BUSY_LOOP in c}
            time.sleep(0.2)
        assert busy, _children(proc.pid)
        proc.send_signal(signal.SIGTERM)
        stdout, stderr = proc.communicate(timeout=60 + 2 * sul.STOP_GRACE_S)
    finally:
        if proc.poll() is None:
            proc.kill()
        # what a failing driver leaves behind (only these busy pids, not another series' busy loops)
        leftovers = [p for p in busy if p in _running_with(sul.BUSY_LOOP)] + _running_with(str(slow))
    try:
        assert proc.returncode == 1, (stdout, stderr)
        assert "stopped (SIGTERM)" in stderr
        # the grace is for a run that ignores SIGINT, not for one that only inherited "ignored"
        assert ("still going" in stderr) == (case == "a-test-ignoring-SIGINT"), stderr
        assert "0 of 0 run(s) passed" in (out / "summary.md").read_text()
        for pid in busy:
            assert not Path(f"/proc/{pid}").exists() or "Z" in Path(f"/proc/{pid}/stat").read_text().split()[2], pid
        # pytest under ./dev's shell stopped too, not left sleeping
        end = time.monotonic() + 30
        while time.monotonic() < end and _running_with(str(slow)):
            time.sleep(0.2)
        assert not _running_with(str(slow))
    finally:
        for pid in leftovers:
            try:
                os.kill(pid, signal.SIGKILL)
            except OSError:
                pass


def _running_with(arg):
    pids = []
    for d in Path("/proc").iterdir():
        try:
            if d.name.isdigit() and arg in (d / "cmdline").read_bytes().decode(errors="replace") \
                    and (d / "stat").read_text().rsplit(")", 1)[1].split()[0] != "Z":
                pids.append(int(d.name))
        except OSError:
            pass
    return pids
