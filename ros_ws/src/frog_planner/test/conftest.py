"""Fixtures of the frog_planner unit tests.

Tests import by path (``--import-mode=importlib``), so the shared helper module
``synthetic_library.py`` is loaded here under a package-unique name and handed out as a fixture.
"""

import importlib.util
from pathlib import Path

import pytest


def _load_helper():
    spec = importlib.util.spec_from_file_location("frog_planner_test_synthetic_library",
                                                  Path(__file__).with_name("synthetic_library.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


SYNTHETIC = _load_helper()


@pytest.fixture(scope="session")
def synthetic():
    """The synthetic-library helper module (library_arrays, write_library, ...)."""
    return SYNTHETIC
