"""Lint (pyflakes + pycodestyle rules via ruff, config in the repository's ruff.toml)."""

import shutil
import subprocess
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1]


def test_ruff_clean():
    ruff = shutil.which("ruff")
    if ruff is None:
        pytest.fail("ruff is not installed (it is in requirements/python.txt)")
    r = subprocess.run([ruff, "check", "--no-cache", str(PACKAGE)], capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr
