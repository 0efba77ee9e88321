"""System-test fixtures: isolated ROS domain, node processes, graph probe, pty serial pairs.

Typical use::

    def test_something(launch, probe):
        rec = launch("recorder", params={"output_dir": str(tmp)})
        probe.wait_for_node("/recorder")
        ...
        assert rec.stop() == 0

Every started process is stopped at teardown (SIGINT to its group, then SIGTERM, SIGKILL)
and its log is printed when the test failed.
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))
from ros_harness import GraphProbe, NodeProcess, acquire_domain, open_pty_pair, ros_args  # noqa: E402

# Generated messages check field ranges only with this set (ROS_ON_PIP.md, Traps).
os.environ["ROS_PYTHON_CHECK_FIELDS"] = "1"

TOOLS = Path(__file__).parent / "tools"
FROG_GRAPH = Path(__file__).resolve().parents[1] / "ros_ws" / "src" / "frog_twin" / "frog_twin" / "config" / \
    "frog_graph.yaml"


def frog_graph_node(name: str, mode: str = "sim", sim_time: bool = False, **params):
    """Node ``name`` of the frog's graph file (the twin's and the real run's), with ``params`` over it.

    System tests that start a part of the graph take its nodes from the one file; without a
    simulator there is no /clock, so ``use_sim_time`` is off unless ``sim_time``.
    """
    from soft_robot_common.graph import load_graph
    overrides = {name: {**({} if sim_time else {"use_sim_time": None}), **params}}
    return load_graph(FROG_GRAPH, mode, overrides)[name]


@pytest.hookimpl(hookwrapper=True, tryfirst=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    rep = outcome.get_result()
    setattr(item, f"rep_{rep.when}", rep)


@pytest.fixture
def one_twin():
    """Hold the machine's one slot for a whole twin (eight node processes, ~1.5 cores): two twins side
    by side on 2 cores starve each other's trackers, and decisions then wait on states older than the
    planner's max_state_age_s. Other tests run beside it; twin tests take turns (a file lock, so
    across pytest-xdist workers)."""
    import fcntl
    with open(Path(tempfile.gettempdir()) / "soft_robot_one_twin.lock", "w") as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


@pytest.fixture
def ros_domain(monkeypatch):
    """An exclusive ROS domain id; the test process's own environment is switched to it."""
    domain = acquire_domain()
    for key in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_PYTHON_CHECK_FIELDS",
                "FASTDDS_BUILTIN_TRANSPORTS"):
        monkeypatch.setenv(key, domain.env[key])
    monkeypatch.delenv("ROS_LOCALHOST_ONLY", raising=False)
    yield domain
    domain.release()


@pytest.fixture
def launch(ros_domain, tmp_path, request):
    """Start an executable (on PATH, or a script in tests/tools) as a node process.

    ``launch(exe, *args, params=None, remap=None, node_name=None, env=None, name=None,
    preexec_fn=None)`` returns a :class:`NodeProcess`; ``exe`` may be a graph node
    (:func:`frog_graph_node`), whose parameters and remaps ``params`` and ``remap`` extend.
    """
    started: list[NodeProcess] = []

    def _launch(exe, *args: str, params=None, remap=None, node_name=None, env=None,
                name=None, preexec_fn=None, cwd=None) -> NodeProcess:
        if not isinstance(exe, str):          # a soft_robot_common.graph.GraphNode: its executable, parameters, remaps
            exe, params, remap = exe.executable, {**exe.parameters, **(params or {})}, {**exe.remaps, **(remap or {})}
        argv = [exe, *args]
        if (TOOLS / exe).is_file():
            argv = [sys.executable, str(TOOLS / exe), *args]
        argv += ros_args(params, remap, node_name)
        name = name or f"{Path(exe).stem}_{len(started)}"
        proc_env = dict(ros_domain.env)
        proc_env.update(env or {})
        proc = NodeProcess(argv, proc_env, tmp_path / f"{name}.log", name,
                           cwd=cwd or tmp_path, preexec_fn=preexec_fn)
        started.append(proc)
        return proc

    yield _launch
    failed = getattr(request.node, "rep_call", None) is not None and request.node.rep_call.failed
    for proc in reversed(started):
        proc.stop()
        if failed:
            print(f"\n----- log of {proc.name} ({proc.log_path}) -----\n"
                  f"{proc.log_text()[-4000:]}")


@pytest.fixture
def probe(ros_domain):
    """A :class:`GraphProbe` node in the test process on the test's domain."""
    p = GraphProbe(ros_domain)
    yield p
    p.close()


@pytest.fixture
def serial_pair():
    """A pseudo-terminal pair: ``(controller_fd, device_path)``; pyserial opens the path."""
    controller, device, path = open_pty_pair()
    yield controller, path
    for fd in (controller, device):
        try:
            os.close(fd)
        except OSError:
            pass


@pytest.fixture
def library(tmp_path):
    """A small kinematic motion library in the contract's file format (frog_planner's test helper)."""
    import importlib.util
    helper = Path(__file__).resolve().parents[1] / "ros_ws" / "src" / "frog_planner" / "test" / "synthetic_library.py"
    spec = importlib.util.spec_from_file_location("system_tests_synthetic_library", helper)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    path = tmp_path / "synthetic.npz"
    mod.write_library(path, n_states=60, horizon=1.5)
    return path
