"""The suite's two tiers, and the guard that keeps the fast one fast.

- **fast** (``./dev test --fast``): every test without the ``system`` or ``slow`` marker. It
  starts no process, no rclpy context and no long simulation: the edit-test loop.
- **system** (``./dev test --system``): the tests marked ``system`` or ``slow``: node processes
  on an isolated ROS domain, command-line tools, process pools, rclpy contexts, long simulations.

``./dev test`` runs both. The markers are declared in pytest.ini.

The fast tier is enforced, not kept by convention. While a test without ``system`` or ``slow``
sets up, runs or tears down, the guard records every process it starts (``subprocess``, and so
``NodeProcess``; ``multiprocessing`` and process pools; ``os.fork``, ``posix_spawn``,
``system``) and every rclpy context it initialises, and fails the test naming them. It also
fails a test whose set-up and call take more than ``FAST_CPU_LIMIT_S`` of CPU time, numba
compilation and session-scoped fixtures (built once per run) not counted: a long simulation
belongs to the system tier. Fast tests over ``FAST_CPU_NOTE_S`` are listed at the end of the
run, to be made cheaper or marked ``slow``. The processes a fast test may start are the short tools named in
``FAST_TOOLS``: ``ruff`` (a package's lint) and ``git`` (the commit ``code_version()`` records),
each done in a fraction of a second and starting no node.
"""

from __future__ import annotations

import fcntl
import multiprocessing.process
import os
import subprocess
import threading
import time
import warnings
from contextlib import contextmanager
from pathlib import Path

import pytest

SYSTEM_MARKERS = ("system", "slow")
# A tripwire for long simulations, far above the ~2.5 s from which tests are marked slow: one
# test's CPU time varies with the machine's load and with what its worker did before (a test
# of 0.4 s alone took 5 s and 10.6 s in loaded runs). Over FAST_CPU_NOTE_S a test is listed.
FAST_CPU_LIMIT_S = 30.0
FAST_CPU_NOTE_S = 5.0
FAST_TOOLS = frozenset({"ruff", "git"})
# Modules whose tier marker lives here rather than in a ``pytestmark`` of their own (the file is
# the better place: move it there when the file is next edited).
MARKED_HERE = {
    "ros_ws/src/frog_twin/test/test_closed_loop.py": "system",     # a process pool builds its library
    "ros_ws/src/frog_twin/test/test_kick_variability.py": "slow",  # minutes of simulated swimming
}


def is_system(item) -> bool:
    """Whether ``item`` belongs to the system tier."""
    return any(item.get_closest_marker(m) is not None for m in SYSTEM_MARKERS)


class TierGuard:
    """What the guarded test started, and the CPU time not to count against it."""

    def __init__(self):
        self.active = False
        self.started: list[str] = []
        self.bystanders: set[threading.Thread] = set()
        self.excluded_cpu = 0.0
        self.compiling = 0
        self.compile_t0 = 0.0

    def begin(self):
        self.active = True
        self.started = []
        # threads left running by earlier tests (a system test's executor) are not this test's
        self.bystanders = set(threading.enumerate()) - {threading.main_thread()}

    def end(self) -> list[str]:
        self.active = False
        return self.started

    def note(self, what: str):
        if self.active and threading.current_thread() not in self.bystanders:
            self.started.append(what)

    def compile_started(self):
        if self.compiling == 0:
            self.compile_t0 = time.process_time()
        self.compiling += 1

    def compile_ended(self):
        self.compiling -= 1
        if self.compiling == 0:
            self.excluded_cpu += time.process_time() - self.compile_t0


GUARD = TierGuard()


def _watch(owner, name, what):
    """Make ``owner.name`` tell the guard ``what(*args)`` (no note if that is empty) before it runs."""
    original = getattr(owner, name)

    def watched(*args, **kwargs):
        note = what(*args, **kwargs)
        if note:
            GUARD.note(note)
        return original(*args, **kwargs)

    watched.__wrapped__ = original
    setattr(owner, name, watched)


def _popen_note(self, args, *rest, **kwargs):
    if isinstance(args, (str, bytes)):
        args = os.fsdecode(args).split() or [""]      # a command line: its first word
    argv0 = os.fsdecode(args if isinstance(args, os.PathLike) else args[0])
    return "" if Path(argv0).name in FAST_TOOLS else f"a process ({argv0})"


def _install_guard():
    _watch(subprocess.Popen, "__init__", _popen_note)
    _watch(multiprocessing.process.BaseProcess, "start",
           lambda self: f"a multiprocessing process ({type(self).__name__})")
    for name in ("fork", "forkpty", "posix_spawn", "posix_spawnp", "system"):
        if hasattr(os, name):
            _watch(os, name, lambda *a, _name=name, **k: f"a process (os.{_name})")
    try:
        import rclpy.context
    except ImportError:
        pass
    else:
        _watch(rclpy.context.Context, "init", lambda *a, **k: "an rclpy context")
    try:
        from numba.core import event
    except ImportError:
        pass
    else:
        class CompileTime(event.Listener):
            def on_start(self, ev):
                GUARD.compile_started()

            def on_end(self, ev):
                GUARD.compile_ended()
        event.register("numba:compile", CompileTime())


def pytest_addoption(parser):
    group = parser.getgroup("tiers", "test tiers (conftest.py at the repository root)")
    group.addoption("--fast", action="store_true",
                    help="only the fast tier: tests that start no process, no rclpy context, no long simulation")
    group.addoption("--system", action="store_true",
                    help="only the system tier: the tests marked 'system' or 'slow'")


def pytest_configure(config):
    if config.getoption("--fast") and config.getoption("--system"):
        raise pytest.UsageError("--fast and --system are the two halves of the suite; give one or neither")
    _install_guard()


@pytest.hookimpl(tryfirst=True)      # before -m selects by marker
def pytest_collection_modifyitems(config, items):
    root = Path(str(config.rootpath))
    for item in items:
        mark = MARKED_HERE.get(Path(os.path.relpath(item.path, root)).as_posix())
        if mark:
            item.add_marker(mark)
    want_system = True if config.getoption("--system") else False if config.getoption("--fast") else None
    if want_system is None:
        return
    keep, drop = [], []
    for item in items:
        (keep if is_system(item) == want_system else drop).append(item)
    if drop:
        config.hook.pytest_deselected(items=drop)
        items[:] = keep


def _fail_if_started(item, phase):
    started = GUARD.end()
    if started:
        pytest.fail(f"{item.nodeid} is in the fast tier but started {', '.join(dict.fromkeys(started))} "
                    f"during its {phase}: mark it 'system' (pytest.ini), or start nothing", pytrace=False)


@contextmanager
def _guarded(item, phase):
    """Watch one phase of a fast test for started processes (the guard ends with the phase)."""
    GUARD.begin()
    try:
        yield
    except BaseException:
        GUARD.end()
        raise
    _fail_if_started(item, phase)


@pytest.hookimpl(wrapper=True)
def pytest_runtest_setup(item):
    if is_system(item):
        return (yield)
    GUARD.excluded_cpu = 0.0
    item.stash[_CPU_AT_SETUP] = time.process_time()
    with _guarded(item, "set-up"):
        return (yield)


@pytest.hookimpl(wrapper=True)
def pytest_runtest_call(item):
    if is_system(item):
        return (yield)
    with _guarded(item, "call"):
        result = yield
    cpu = time.process_time() - item.stash[_CPU_AT_SETUP] - GUARD.excluded_cpu
    if cpu > FAST_CPU_NOTE_S:
        item.user_properties.append(("fast_tier_cpu_s", round(cpu, 1)))
    if cpu > FAST_CPU_LIMIT_S:
        pytest.fail(f"{item.nodeid} is in the fast tier but its set-up and call took {cpu:.1f} s of CPU "
                    f"(limit {FAST_CPU_LIMIT_S:.0f} s, numba compilation and session fixtures not counted): "
                    f"make it cheaper or mark it 'slow' (pytest.ini)", pytrace=False)
    return result


def pytest_terminal_summary(terminalreporter):
    heavy = []
    for reports in terminalreporter.stats.values():
        for r in reports:
            cpu = dict(getattr(r, "user_properties", ())).get("fast_tier_cpu_s")
            if cpu is not None and getattr(r, "when", "") == "call":
                heavy.append((cpu, r.nodeid))
    if heavy:
        terminalreporter.write_sep("-", f"fast-tier tests over {FAST_CPU_NOTE_S:.0f} s of CPU: make them cheaper, "
                                        f"or mark them 'slow' if they are in every run")
        for cpu, nodeid in sorted(heavy, reverse=True):
            terminalreporter.write_line(f"{cpu:6.1f} s  {nodeid}")


@pytest.hookimpl(wrapper=True)
def pytest_runtest_teardown(item, nextitem):
    if is_system(item):
        return (yield)
    with _guarded(item, "teardown"):
        return (yield)


@pytest.hookimpl(wrapper=True)
def pytest_fixture_setup(fixturedef, request):
    """Session-scoped fixtures are built once per run: their CPU time is not the test's."""
    if fixturedef.scope != "session" or not GUARD.active:
        return (yield)
    t0, excluded = time.process_time(), GUARD.excluded_cpu
    try:
        return (yield)
    finally:
        GUARD.excluded_cpu = excluded + time.process_time() - t0


_CPU_AT_SETUP = pytest.StashKey[float]()


# ---- built once per run, for every worker -------------------------------------------------------

KERNEL_PACKAGES = ("frog_sim", "frog_twin", "softkin_fk")   # their tests run numba kernels


@contextmanager
def _run_lock(path: Path):
    """An exclusive lock on ``path`` across processes (the pytest-xdist workers)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w") as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


def _run_folder(tmp_path_factory) -> Path:
    """A folder all workers of this run share (pytest's base folder of the run)."""
    base = tmp_path_factory.getbasetemp()
    return base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base


def _needs_kernels(item) -> bool:
    parts = Path(os.path.relpath(item.path, item.config.rootpath)).parts
    return is_system(item) or (parts[:2] == ("ros_ws", "src") and parts[2] in KERNEL_PACKAGES)


def _compile_kernels():
    """Run the simulator (with the twin's realism), a rollout and the finger's FK once, briefly."""
    from frog_sim.core.rollouts import Rollouts
    from frog_sim.core.simulation import FrogSimulation
    from softkin_fk.core.forward import ForwardSolver
    from softkin_fk.core.models import build_tendon_finger
    sim = FrogSimulation()
    sim.set_realism(seed=0, limb_strength_sd=0.1, kick_strength_sd=0.1, yaw_disturbance_sd=1e-5)
    sim.execute_primitive("A")
    sim.run(0.1)
    with Rollouts(threads=1) as rollouts:
        rollouts.rollout_batch(rollouts.start_from_simulation(sim), [["B"]], period=0.05)
    ForwardSolver(build_tendon_finger(resolution=1)).solve([1, 1, 0.99], tol=1e-6)


@pytest.fixture(scope="session", autouse=True)
def compiled_kernels(request):
    """The numba kernels compiled once per run, before the first test that runs them.

    They are cached on disk (``cache=True``), but on a fresh clone every process that runs them
    before the cache exists compiles them too: each worker, and each node, library worker or tool
    a system test starts (about 90 s of CPU apiece). The first worker compiles them here while
    the other waits on the lock; then every process loads them from the cache (about 1.5 s of
    CPU). A failure here only warns: the tests that run the kernels say what is wrong.
    """
    if not any(_needs_kernels(item) for item in request.session.items):
        return
    with _run_lock(Path(str(request.config.rootpath)) / "runs" / ".kernels.lock"):
        try:
            _compile_kernels()
        except Exception as exc:          # an optimisation: the tests that run the kernels report it
            warnings.warn(f"compiling the numba kernels before the tests failed: {exc!r}", stacklevel=1)


@pytest.fixture(scope="session")
def motion_library(tmp_path_factory):
    """``motion_library(n_states, horizon, seed) -> Path``: a motion library generated once per run.

    Each spec is generated once for all workers (the first to ask builds it, under a lock, with a
    process pool of 2), so modules asking for the same library share it.
    """
    folder = _run_folder(tmp_path_factory) / "motion_libraries"

    def get(n_states: int, horizon: float, seed: int) -> Path:
        from frog_sim.core.motion_library import LibrarySpec, generate_library
        path = folder / f"library_{n_states}_{horizon:g}_{seed}.npz"
        with _run_lock(path.with_suffix(".lock")):
            if not path.exists():
                generate_library(LibrarySpec(n_states=n_states, horizon=horizon, seed=seed), path, workers=2,
                                 chunk_size=10, progress=False)
        return path
    return get
