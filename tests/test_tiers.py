"""The tiers (conftest.py at the repository root): a test that starts a process, an rclpy context
or a long computation without the ``system`` or ``slow`` marker fails; --fast and --system pick
the two halves. Each check runs a small suite with the repository's conftest.py and pytest.ini in
a pytest process of its own."""

import re
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.system        # it starts pytest processes

ROOT = Path(__file__).resolve().parents[1]

SUITE = '''
import multiprocessing
import subprocess
import threading
import time

import pytest


def _busy(seconds):
    t = time.process_time()
    while time.process_time() - t < seconds:
        pass


@pytest.fixture(scope="module")
def started_in_a_fixture():
    subprocess.run(["true"], check=True)


def test_process(tmp_path):
    subprocess.run(["true"], check=True)


def test_process_in_a_thread_it_started():
    t = threading.Thread(target=subprocess.run, args=(["true"],))
    t.start()
    t.join()


def test_process_in_a_fixture(started_in_a_fixture):
    pass


def test_multiprocessing():
    p = multiprocessing.get_context("spawn").Process(target=print)
    p.start()
    p.join()


def test_rclpy_context():
    import rclpy
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    rclpy.shutdown(context=ctx)


def test_long_computation():
    _busy(1.5)


def test_noted_computation():
    _busy(0.7)


def test_numba_compilation_is_not_counted():
    import numba
    import numpy as np
    f = numba.njit(lambda a, b: (a * b).sum() + a.max())
    t = time.process_time()
    types = (np.float64, np.float32, np.int64, np.int32, np.int16, np.uint8, np.uint16, np.uint32, np.uint64)
    for kind in types * 3:
        if time.process_time() - t > 1.5:
            break
        f = numba.njit(lambda a, b: (a * b).sum() + a.max())
        f(np.ones(3, kind), np.ones(3, kind))
    assert time.process_time() - t > 1.5, "compiled too little to tell"


def test_quick_tools():
    subprocess.run(["ruff", "--version"], check=True, capture_output=True)
    subprocess.run(["git", "--version"], check=True, capture_output=True)


def test_nothing_started():
    assert sum(range(1000)) == 499500


@pytest.mark.system
def test_system_may_start_processes():
    subprocess.run(["true"], check=True)


@pytest.mark.slow
def test_slow_may_compute():
    _busy(1.5)
'''

GUARDED = {"test_process": "a process (true) during its call",
           "test_process_in_a_thread_it_started": "a process (true) during its call",
           "test_process_in_a_fixture": "a process (true) during its set-up",
           "test_multiprocessing": "a multiprocessing process",
           "test_rclpy_context": "an rclpy context",
           "test_long_computation": "s of CPU (limit 1 s"}
PASS = {"test_numba_compilation_is_not_counted", "test_quick_tools", "test_nothing_started", "test_noted_computation",
        "test_system_may_start_processes", "test_slow_may_compute"}
SYSTEM = {"test_system_may_start_processes", "test_slow_may_compute"}


@pytest.fixture
def suite(tmp_path, ros_domain):          # the rclpy context on a domain of its own
    conftest = (ROOT / "conftest.py").read_text()
    conftest, n = re.subn(r"^FAST_CPU_LIMIT_S = .*$", "FAST_CPU_LIMIT_S = 1.0", conftest, flags=re.M)
    conftest, m = re.subn(r"^FAST_CPU_NOTE_S = .*$", "FAST_CPU_NOTE_S = 0.5", conftest, flags=re.M)
    assert n == m == 1
    (tmp_path / "conftest.py").write_text(conftest)
    ini = (ROOT / "pytest.ini").read_text()
    (tmp_path / "pytest.ini").write_text(re.sub(r"^testpaths = .*$", "testpaths = .", ini, flags=re.M))
    (tmp_path / "test_suite.py").write_text(SUITE)
    return tmp_path


def _pytest(folder, *args):
    r = subprocess.run([sys.executable, "-m", "pytest", "-n", "0", "-p", "no:cacheprovider", "-rA", *args],
                       cwd=folder, capture_output=True, text=True, timeout=300)
    return r.stdout + r.stderr


def _outcomes(out):
    found = re.findall(r"^(PASSED|FAILED|ERROR) test_suite\.py::(\w+)", out, flags=re.M)
    return {name: outcome for outcome, name in found}


def test_the_guard_fails_what_does_not_belong_in_the_fast_tier(suite):
    out = _pytest(suite)
    outcomes = _outcomes(out)
    assert {name: outcomes.get(name) for name in PASS} == dict.fromkeys(PASS, "PASSED"), out[-4000:]
    for name, words in GUARDED.items():
        assert outcomes.get(name) in ("FAILED", "ERROR"), (name, out[-4000:])
        said = rf"test_suite\.py::{name} is in the fast tier but .*{re.escape(words)}"
        assert re.search(said, out), (name, out[-4000:])
    # a fast test over the note's CPU time is listed at the end, and only such a one
    listed = out.split("fast-tier tests over")[-1].split("short test summary info")[0]
    assert re.search(r"^ +0\.[7-9] s  test_suite\.py::test_noted_computation$", listed, flags=re.M), out[-2000:]
    assert "test_nothing_started" not in listed and "test_slow_may_compute" not in listed


def test_fast_and_system_are_the_two_halves(suite):
    fast = set(re.findall(r"test_suite\.py::(\w+)", _pytest(suite, "--fast", "--collect-only", "-q")))
    system = set(re.findall(r"test_suite\.py::(\w+)", _pytest(suite, "--system", "--collect-only", "-q")))
    every = set(re.findall(r"^def (test_\w+)", SUITE, flags=re.M))
    assert system == SYSTEM and fast == every - SYSTEM


def test_modules_marked_in_conftest_exist(request):
    root_conftest, = (p for p in request.config.pluginmanager.get_plugins()
                      if getattr(p, "__file__", None) == str(ROOT / "conftest.py"))
    assert root_conftest.MARKED_HERE
    for path, mark in root_conftest.MARKED_HERE.items():
        assert (ROOT / path).is_file(), path
        assert mark in ("system", "slow")
