"""Request checks of the kinematics core: thresholds, iteration limits and waypoint counts.

NaN compares False with every bound, so each check must refuse it explicitly; these run
without a mesh (the checks do not need one).
"""
import math

import pytest

from softkin_fk.core.kinematics import (LAM_RANGE, MAX_ITERATIONS, RequestError, check_iterations,
                                        check_tolerance)


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf, -1.0, LAM_RANGE[1] * 2, LAM_RANGE[0] / 2])
def test_tolerance_refused_with_its_value(bad):
    with pytest.raises(RequestError, match=r"^tolerance "):
        check_tolerance(bad, 2e-4)


def test_tolerance_zero_is_the_default_and_range_ends_are_accepted():
    assert check_tolerance(0.0, 2e-4) == 2e-4
    assert check_tolerance(LAM_RANGE[0], 2e-4) == LAM_RANGE[0]
    assert check_tolerance(LAM_RANGE[1], 2e-4) == LAM_RANGE[1]


def test_iteration_limit():
    assert check_iterations(0, 30) == 30 and check_iterations(MAX_ITERATIONS, 30) == MAX_ITERATIONS
    with pytest.raises(RequestError, match="max_iterations 4000000000"):
        check_iterations(4_000_000_000, 30)
