"""Stable device paths of emulated serial devices: one per namespace, held by one process.

An emulator links its pty to a stable path (``/tmp/frog_robot_tty``) that a driver opens.
Two emulators on one path would silently re-point the link, and the first to exit would
remove it under the other. So:

- :func:`namespaced_path` gives the default path for the node's namespace
  (``/tmp/frog_robot_tty`` in ``/``, ``/tmp/frog_robot_tty_frog2`` in ``/frog2``), so
  ``-r __ns:=/frog2`` moves the device with the topics;
- :class:`PathClaim` holds ``<path>.lock`` (``flock``, with the owner's pid inside) for the
  node's lifetime and refuses, with a :class:`ConfigurationError` naming the owner, a path
  that a live process holds. The lock goes with the process, however it ends.
"""

from __future__ import annotations

import fcntl
import os

from .parameters import ConfigurationError


def namespaced_path(base: str, namespace: str) -> str:
    """``base`` for the root namespace, else ``base`` + ``_`` + the namespace with ``/`` as ``_``."""
    ns = namespace.strip("/")
    return base if not ns else f"{base}_{ns.replace('/', '_')}"


class PathClaim:
    """Exclusive use of a device path by this process (``<path>.lock``, flock + pid)."""

    def __init__(self, path: str, what: str = "link_path"):
        self.path = path
        self.lock_path = f"{path}.lock"
        folder = os.path.dirname(os.path.abspath(path))
        if not os.path.isdir(folder):
            raise ConfigurationError(f"{what} {path!r}: folder {folder!r} does not exist")
        try:
            self._file = open(self.lock_path, "a+")
        except OSError as exc:
            raise ConfigurationError(f"{what} {path!r}: cannot create {self.lock_path!r}: {exc.strerror}") from None
        try:
            fcntl.flock(self._file, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            self._file.seek(0)
            owner = self._file.read().strip() or "unknown"
            self._file.close()
            self._file = None
            raise ConfigurationError(
                f"{what} {path!r} is in use by another live process (pid {owner}, lock {self.lock_path}); "
                f"stop it, or give this node its own {what} (or namespace)") from None
        self._file.seek(0)
        self._file.truncate()
        self._file.write(f"{os.getpid()}\n")
        self._file.flush()

    def release(self) -> None:
        """Give the path up (the lock file stays: removing it could let two processes lock two files)."""
        if self._file is None:
            return
        self._file.close()
        self._file = None
