"""Start node processes on an isolated ROS 2 domain and stop them cleanly (no rclpy needed).

Used by the main job, the twin entry scripts, the system tests and the benchmarks. Every
process runs in its own session (process group) so a stop reaches the node and any
children: SIGINT first (a node's normal shutdown), then SIGTERM, then SIGKILL; a node also
stops by itself when the process that started it dies, even by SIGKILL. A domain id
is held exclusively through a lock file, so concurrent runs on one machine never share DDS
traffic.
"""

from __future__ import annotations

import fcntl
import os
import re
import shutil
import signal
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Optional

#: set in a started node's environment to the starting process's pid: the node stops when that dies
PARENT_PID_ENV = "SOFT_ROBOT_PARENT_PID"
DOMAIN_RANGE = range(120, 230)   # Fast DDS ports overflow above domain 232
LOCK_DIR = Path("/tmp/soft_robot_test_domains")
#: Fast DDS transports of every node we start: UDP only. With the shared-memory transport (the
#: default) a writer's publish() blocked for ~1 s after a reader's process was SIGKILLed
#: (scripts/dds_writer_block_repro.py: 9 of 355 s; UDPv4 0 of 357 s), once for good in the
#: fault tests (docs/faults.md, "The whole suite under load").
FASTDDS_TRANSPORTS = "UDPv4"
# How long a process's middleware teardown (destroy_node, rclpy.shutdown) may take [s] before it is
# left behind, saying where it was: Fast DDS can block for good there (docs/faults.md). Below
# NodeProcess.stop's 10 s wait for SIGINT.
MIDDLEWARE_TEARDOWN_S = 6.0


@dataclass
class RosDomain:
    """An exclusively held ROS domain id and the environment that selects it."""

    domain_id: int
    env: dict
    _lock_file: object = field(default=None, repr=False)

    def release(self) -> None:
        if self._lock_file is not None:
            self._lock_file.close()
            self._lock_file = None


def acquire_domain(base_env: Optional[dict] = None) -> RosDomain:
    """Pick a domain id no other run on this machine holds (lock files); localhost discovery, UDP."""
    LOCK_DIR.mkdir(exist_ok=True)
    start = (os.getpid() * 7919 + time.monotonic_ns()) % len(DOMAIN_RANGE)
    for i in range(len(DOMAIN_RANGE)):
        domain = DOMAIN_RANGE[(start + i) % len(DOMAIN_RANGE)]
        f = open(LOCK_DIR / f"{domain}.lock", "w")
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            f.close()
            continue
        env = dict(os.environ if base_env is None else base_env)
        env.update(ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
                   ROS_PYTHON_CHECK_FIELDS="1", PYTHONUNBUFFERED="1",
                   RCUTILS_COLORIZED_OUTPUT="0", FASTDDS_BUILTIN_TRANSPORTS=FASTDDS_TRANSPORTS)
        env.pop("ROS_LOCALHOST_ONLY", None)  # deprecated in Jazzy; conflicts with the range
        return RosDomain(domain, env, f)
    raise RuntimeError(f"no free ROS domain id in {DOMAIN_RANGE}")


class NodeProcess:
    """One started executable: its log file, its exit, and a clean stop."""

    def __init__(self, argv: list[str], env: dict, log_path: Path, name: str,
                 cwd: Optional[Path] = None, preexec_fn: Optional[Callable] = None):
        exe = shutil.which(argv[0], path=env.get("PATH"))
        if exe is None:
            raise FileNotFoundError(
                f"executable {argv[0]!r} is not on PATH; run the tests through './dev test' "
                f"so the workspace is built and sourced")
        self.name = name
        self.argv = [exe, *argv[1:]]
        self.log_path = Path(log_path)
        self._log = open(self.log_path, "wb")
        self.started_at = time.monotonic()
        env = dict(env, **{PARENT_PID_ENV: str(os.getpid())})
        self.proc = subprocess.Popen(self.argv, env=env, cwd=cwd, stdout=self._log,
                                     stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                     start_new_session=True, preexec_fn=preexec_fn)
        self.stop_signal: Optional[str] = None   # which signal finally ended it
        self.stop_seconds: Optional[float] = None  # how long stop() took

    @property
    def pid(self) -> int:
        return self.proc.pid

    def running(self) -> bool:
        return self.proc.poll() is None

    def log_text(self) -> str:
        if not self._log.closed:
            self._log.flush()
        return self.log_path.read_text(errors="replace")

    def wait_for_log(self, pattern: str, timeout: float = 10.0) -> re.Match:
        """Wait until the process log matches ``pattern`` (regex); raise on timeout/exit."""
        rx = re.compile(pattern)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            m = rx.search(self.log_text())
            if m:
                return m
            if not self.running():
                raise AssertionError(f"{self.name} exited (code {self.proc.returncode}) before "
                                     f"logging {pattern!r}:\n{self.log_text()[-3000:]}")
            time.sleep(0.05)
        raise TimeoutError(f"{self.name} did not log {pattern!r} within {timeout} s:\n"
                           f"{self.log_text()[-3000:]}")

    def wait(self, timeout: float) -> int:
        return self.proc.wait(timeout)

    def send(self, sig: int) -> None:
        try:
            os.killpg(self.proc.pid, sig)
        except ProcessLookupError:
            pass

    def stop(self, sigint_timeout: float = 10.0, sigterm_timeout: float = 5.0) -> int:
        """SIGINT the process group, escalating to SIGTERM then SIGKILL; return the code."""
        t0 = time.monotonic()
        for sig, timeout in ((signal.SIGINT, sigint_timeout), (signal.SIGTERM, sigterm_timeout),
                             (signal.SIGKILL, 10.0)):
            if not self.running():
                break
            self.send(sig)
            try:
                self.proc.wait(timeout)
                self.stop_signal = self.stop_signal or sig.name
            except subprocess.TimeoutExpired:
                continue
        # Reap anything left in the group (children of a wrapper).
        try:
            os.killpg(self.proc.pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass
        self._log.close()
        self.stop_seconds = time.monotonic() - t0
        return self.proc.returncode

    def stop_report(self) -> dict:
        """How the last stop() went: the signal that ended it, the exit code, the seconds it took."""
        return {"signal": self.stop_signal, "code": self.proc.returncode,
                "seconds": None if self.stop_seconds is None else round(self.stop_seconds, 2)}

    @property
    def stopped_cleanly(self) -> bool:
        return self.stop_signal in (None, "SIGINT") and self.proc.returncode == 0


def ros_args(params: Optional[dict] = None, remap: Optional[dict] = None,
             node_name: Optional[str] = None) -> list[str]:
    """``--ros-args`` for parameters (typed as Python values), remappings, node name."""
    out: list[str] = []
    for k, v in (params or {}).items():
        out += ["-p", f"{k}:={_param_literal(v)}"]
    for k, v in (remap or {}).items():
        out += ["-r", f"{k}:={v}"]
    if node_name:
        out += ["-r", f"__node:={node_name}"]
    return ["--ros-args", *out] if out else []


def _param_literal(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, (list, tuple)):
        return "[" + ",".join(_param_literal(x) for x in v) + "]"
    if isinstance(v, str):
        # quote what YAML would read as a number, a boolean (Y, no, on, ...) or null
        yaml_words = r"[-+0-9.eE]+|(?i:true|false|y|n|yes|no|on|off|null)|~"
        return "'" + v + "'" if v == "" or re.fullmatch(yaml_words, v) else v
    return str(v)
