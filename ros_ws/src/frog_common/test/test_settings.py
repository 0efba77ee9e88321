"""setting() fields, the one range check, sentinels and cross-checks."""

import dataclasses
import math

import numpy as np
import pytest
from frog_common.settings import (Settings, check, describe, field_problem, from_params, param_name, range_problem,
                                  setting, to_core, to_param)


@dataclasses.dataclass(frozen=True)
class Example(Settings):
    gain: float = setting(1.0, "a gain", min=0.0, max=2.0, unit="1/m", live=True)
    count: int = setting(3, "a count", min=1, max=5)
    mode: str = setting("e", "a mode", choices=("e", "r"))
    on: bool = setting(True, "a switch")
    names: tuple = setting(("a", "b"), "some names")
    drag: float = setting(math.inf, "drag time; 0 = none", min=0.1, max=10.0, sentinel=(0.0, math.inf),
                          param="drag_time")
    low: float = setting(0.5, "at most high", min=0.0, max=1.0)
    high: float = setting(0.8, "at least low", min=0.0, max=1.0)

    def cross_check(self):
        return f"low={self.low} must be <= high={self.high}" if self.low > self.high else None


def test_defaults_build_and_every_bound_is_inclusive():
    e = Example()
    assert e.names == ("a", "b") and e.drag == math.inf
    Example(gain=0.0, count=1)
    Example(gain=2.0, count=5)


@pytest.mark.parametrize("change, message", [
    ({"gain": -0.1}, "gain=-0.1 is below its minimum 0.0"),
    ({"gain": 2.5}, "gain=2.5 is above its maximum 2.0"),
    ({"gain": math.nan}, "gain=nan must be finite"),
    ({"count": 0}, "count=0 is below its minimum 1"),
    ({"count": 2.5}, "count=2.5 must be int"),
    ({"count": True}, "count=True must be int"),
    ({"mode": "x"}, "mode='x' is not one of 'e', 'r'"),
    ({"on": 1}, "on=1 must be bool"),
    ({"names": "ab"}, "names='ab' must be tuple"),
    ({"drag": 0.05}, "drag=0.05 is below its minimum 0.1"),
    ({"drag": -math.inf}, "drag=-inf must be finite"),
    ({"low": 0.9, "high": 0.1}, "low=0.9 must be <= high=0.1"),
])
def test_a_bad_value_is_refused_with_its_name(change, message):
    with pytest.raises(ValueError) as err:
        Example(**change)
    assert str(err.value) == message
    assert check(dataclasses.replace(Example(), **{})) is None


def test_numpy_scalars_and_ints_for_floats_are_accepted():
    Example(gain=np.float64(1.5), count=np.int64(2), on=np.bool_(False), high=1)


def test_replace_checks():
    e = Example().replace(gain=1.5)
    assert e.gain == 1.5
    with pytest.raises(ValueError, match="gain"):
        Example().replace(gain=3.0)


def test_sentinel_round_trip_and_param_names():
    f = {f.name: f for f in dataclasses.fields(Example)}
    assert param_name(f["drag"]) == "drag_time" and param_name(f["gain"]) == "gain"
    assert to_param(f["drag"], math.inf) == 0.0 and to_core(f["drag"], 0.0) == math.inf
    assert to_param(f["drag"], 2.0) == 2.0 and to_core(f["drag"], 2.0) == 2.0
    assert to_param(f["names"], ("a",)) == ["a"] and to_core(f["names"], ["a"]) == ("a",)
    assert field_problem(f["drag"], math.inf) is None
    e = from_params(Example, {"drag_time": 3.0, "gain": 0.5, "names": ["x"], "unrelated": 1})
    assert (e.drag, e.gain, e.names, e.count) == (3.0, 0.5, ("x",), 3)
    base = Example(count=4)
    assert from_params(Example, {"gain": 0.1}, base=base).count == 4
    assert from_params(Example, {}, gain=0.2).gain == 0.2


def test_range_problem_alone_and_describe():
    assert range_problem("x", 1.0, 0.0, 1.0) is None
    assert range_problem("x", 1.0001, 0.0, 1.0) == "x=1.0001 is above its maximum 1.0"
    assert range_problem("x", "a", choices=("b",)) == "x='a' is not one of 'b'"
    assert range_problem("x", True, 2, 3) is None          # booleans have no range
    f = {f.name: f for f in dataclasses.fields(Example)}
    assert describe(f["gain"]) == "a gain [1/m]" and describe(f["mode"]) == "a mode"
