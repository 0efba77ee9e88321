"""Shared fixtures of the frog_sim tests: measured data are optional.

Tests that compare against the authors' measurements get them through ``measured_file``;
in a clone without ``FROG_DATA_DIR`` / ``shared/data/frog`` they skip with a reason that
names the missing file.
"""
import pytest

from frog_sim.core.actuation import find_data_file


@pytest.fixture(scope="session")
def measured_file():
    """``measured_file(name) -> Path`` of a file of shared/data/frog, or skip naming it."""
    def get(name):
        try:
            return find_data_file(name)
        except FileNotFoundError as exc:
            pytest.skip(f"measured data not available: {exc}")
    return get
