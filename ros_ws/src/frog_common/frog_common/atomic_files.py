"""Files that are either absent or complete: a crash mid-write never leaves half a file."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np


def atomic_save_npz(path, arrays: dict) -> None:
    """Write an .npz so that ``path`` is either absent or complete (rename is atomic)."""
    _atomic_write(path, lambda f: np.savez(f, **arrays))


def atomic_write_text(path, text: str) -> None:
    """Write ``text`` (UTF-8) so that ``path`` is either absent or complete; its folder is made."""
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    _atomic_write(path, lambda f: f.write(text.encode()))


def _atomic_write(path, write) -> None:
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=path.name + ".", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
