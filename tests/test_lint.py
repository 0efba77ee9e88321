"""Lint of the non-package code: tests, benchmarks, scripts (config in ruff.toml)."""

import shutil
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_ruff_clean():
    ruff = shutil.which("ruff")
    assert ruff, "ruff is not installed (it is in requirements/python.txt)"
    r = subprocess.run([ruff, "check", "--no-cache", "tests", "bench", "scripts"], cwd=ROOT,
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr
