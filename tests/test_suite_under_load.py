"""scripts/suite_under_load.py: its busy processes load the CPU, its runs report exit code and CPU
time as the kernel counts them, and it reads pytest's result line in both output styles."""

import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "scripts"))
import suite_under_load as sul  # noqa: E402


def _cpu_seconds(pid):
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / 100.0       # utime + stime, clock ticks (USER_HZ 100)


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
