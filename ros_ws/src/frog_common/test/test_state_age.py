"""The state-age rule shared by the planner and the bridge."""

import pytest

from frog_common.state_age import MAX_STATE_AGE_S, StateAgeSettings, command_state, state_age_problem


def test_a_command_state_is_its_state_stamp_else_its_stamp_else_now():
    assert command_state(9.5, 9.9, 10.0) == 9.5
    assert command_state(0.0, 9.9, 10.0) == 9.9
    assert command_state(0.0, 0.0, 10.0) == 10.0


@pytest.mark.parametrize("age, ok", [(0.0, True), (0.5, True), (4.4 - 3.9, True), (0.500002, False), (-0.5, True),
                                     (-0.6, False)])
def test_the_bound_is_inclusive_and_a_future_stamp_beyond_it_is_refused(age, ok):
    problem = state_age_problem(age, 0.5)
    assert (problem is None) == ok
    if not ok:
        assert ("future" in problem) == (age < 0)


def test_the_setting_has_one_default_and_a_range():
    assert StateAgeSettings().max_state_age_s == MAX_STATE_AGE_S
    with pytest.raises(ValueError, match="max_state_age_s"):
        StateAgeSettings(max_state_age_s=0.0)
