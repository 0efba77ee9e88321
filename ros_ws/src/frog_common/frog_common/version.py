"""One code version for every file the packages write (libraries, fits, reports)."""

from __future__ import annotations

import subprocess
from functools import lru_cache
from pathlib import Path


@lru_cache(maxsize=None)
def code_version(package: str) -> str:
    """``'<package> <version> (git <rev>)'``: the installed distribution's version, and the
    commit of the checkout the code runs from when it is one (``'unknown'`` / no git part
    otherwise), so a file records what produced it."""
    try:
        from importlib.metadata import version
        v = version(package)
    except Exception:                 # not installed as a distribution
        v = 'unknown'
    try:
        rev = subprocess.run(['git', 'rev-parse', '--short', 'HEAD'], capture_output=True, text=True,
                             cwd=Path(__file__).parent, timeout=5).stdout.strip()
    except Exception:                 # no git, or not a checkout
        rev = ''
    return f'{package} {v}' + (f' (git {rev})' if rev else '')
