#!/usr/bin/env python3
"""Run the test suite N times in a row beside K busy processes: do the tests hold under load?

Each run is the README's test command, ``./dev test`` (pytest arguments after ``--`` are passed
on). The busy processes spin a CPU core each for the whole series, so the suite's node processes
get what a loaded 2-core machine leaves them. The series stops at the first failed run unless
``--keep-going``. Each run's output goes to ``OUT/run_K.log``; the summary (one row per run: exit
code, pytest's result line, wall and CPU time) is printed and written to ``OUT/summary.md``.
Ctrl-C, SIGTERM (``kill``, ``timeout``) or SIGHUP stop the run under way (SIGINT to its process
group, as Ctrl-C in a terminal; SIGTERM, then SIGKILL, if it is still running STOP_GRACE_S later)
and the busy processes, and still write the summary. The runs get the default SIGINT action even
when this script was started with SIGINT ignored (``cmd &`` in a script ignores it, and children
inherit that), so that the stop reaches pytest.

Examples:
  python scripts/suite_under_load.py                                   # the whole suite, 5 x, 2 busy
  python scripts/suite_under_load.py --runs 1 --busy 2 -- -m system -q # the system tests once
  python scripts/suite_under_load.py --runs 3 --busy 0 -- tests/test_bridge_system.py -q
"""

import argparse
import os
import re
import signal
import subprocess
import sys
import time
from datetime import datetime
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
BUSY_LOOP = "while True: pass"
# "=== 3 passed in 1.2s ===", or with -q "3 passed in 1.2s"
#: seconds a stopped run gets after SIGINT (pytest's summary), then after SIGTERM, before the next signal
STOP_GRACE_S = 20.0
RESULT_LINE = re.compile(r"^=*\s*((\d+ \w+.*|no tests ran.*) in [\d.]+s( \([\d:]+\))?)\s*=*$")


def start_busy(count: int) -> list[subprocess.Popen]:
    return [subprocess.Popen([sys.executable, "-c", BUSY_LOOP], stdin=subprocess.DEVNULL,
                             start_new_session=True) for _ in range(count)]


def stop_busy(procs: list[subprocess.Popen]) -> None:
    for p in procs:
        if p.poll() is None:
            p.kill()
        p.wait()


def result_line(log: Path) -> str:
    """pytest's last '==== ... passed ... ====' line, or '' when it printed none."""
    found = ""
    with open(log, errors="replace") as f:
        for line in f:
            m = RESULT_LINE.match(line.strip())
            if m:
                found = m.group(1)
    return found


def _stop_signal(signum, frame):
    """SIGTERM, SIGHUP: stop as Ctrl-C does (the busy processes would otherwise spin on)."""
    raise KeyboardInterrupt(signal.Signals(signum).name)


def stop_group(p: subprocess.Popen) -> None:
    """SIGINT to the run's process group (Ctrl-C), then SIGTERM and SIGKILL to what is left."""
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL):
        try:
            os.killpg(p.pid, sig)
        except ProcessLookupError:
            break
        try:
            p.wait(STOP_GRACE_S)
            break
        except subprocess.TimeoutExpired:
            print(f"suite_under_load: the run is still going {STOP_GRACE_S:g} s after {sig.name}", file=sys.stderr)
    p.wait()


def run_once(cmd: list[str], log: Path) -> tuple[int, float, float]:
    """Exit code, wall seconds and CPU seconds (user + system, the run and all it waited for)."""
    t0 = time.monotonic()
    with open(log, "w") as f:
        # its own process group: a stop reaches pytest under ./dev's shell, not the shell alone
        p = subprocess.Popen(cmd, cwd=ROOT, stdout=f, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                             start_new_session=True)
        try:
            _, status, usage = os.wait4(p.pid, 0)
        except KeyboardInterrupt:
            stop_group(p)
            raise
        p.returncode = os.waitstatus_to_exitcode(status)
    return p.returncode, time.monotonic() - t0, usage.ru_utime + usage.ru_stime


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=5, help="runs in a row (default 5)")
    ap.add_argument("--busy", type=int, default=2, help="busy processes beside them (default 2)")
    ap.add_argument("--keep-going", action="store_true", help="go on after a failed run")
    ap.add_argument("--out", type=Path, default=None, help="log folder (default runs/suite_load_<time>)")
    ap.add_argument("pytest_args", nargs="*", help="after --: passed to ./dev test")
    args = ap.parse_args(argv)
    if args.runs < 1 or args.busy < 0:
        ap.error(f"--runs {args.runs} --busy {args.busy}: expected at least 1 run and 0 or more busy processes")
    out = args.out or ROOT / "runs" / f"suite_load_{datetime.now():%Y%m%d_%H%M%S}"
    out.mkdir(parents=True, exist_ok=True)
    cmd = [str(ROOT / "dev"), "test", *args.pytest_args]
    rows, failed = [], 0
    for sig in (signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, _stop_signal)
    # a handler (not SIG_IGN) is reset to the default in the runs: Ctrl-C and the stop reach pytest
    signal.signal(signal.SIGINT, signal.default_int_handler)
    busy = start_busy(args.busy)
    try:
        for k in range(1, args.runs + 1):
            log = out / f"run_{k}.log"
            print(f"[{k}/{args.runs}] {' '.join(cmd[1:])} beside {args.busy} busy process(es) -> {log}", flush=True)
            code, wall, cpu = run_once(cmd, log)
            line = result_line(log) or "(no pytest result line)"
            rows.append((k, code, line, wall, cpu))
            print(f"    exit {code}: {line}; wall {wall:.0f} s, CPU {cpu:.0f} s", flush=True)
            if code != 0:
                failed += 1
                if not args.keep_going:
                    break
    except KeyboardInterrupt as stop:
        print(f"suite_under_load: stopped ({stop.args[0] if stop.args else 'Ctrl-C'})", file=sys.stderr)
    finally:
        stop_busy(busy)
    table = ["| run | exit | pytest | wall s | CPU s |", "|---|---|---|---|---|"]
    table += [f"| {k} | {code} | {line} | {wall:.0f} | {cpu:.0f} |" for k, code, line, wall, cpu in rows]
    passed = len(rows) - failed
    summary = (f"`./dev test {' '.join(args.pytest_args)}` x {args.runs} beside {args.busy} busy process(es), "
               f"{os.cpu_count()} cores: {passed} of {len(rows)} run(s) passed\n\n" + "\n".join(table) + "\n")
    (out / "summary.md").write_text(summary)
    print(summary, end="")
    return 0 if rows and failed == 0 and len(rows) == args.runs else 1


if __name__ == "__main__":
    sys.exit(main())
