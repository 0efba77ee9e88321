"""Param tables: descriptors, start-up checks, live sets, undeclared overrides (in-process rclpy)."""

import dataclasses
import math

import pytest
import rclpy
from frog_common.settings import Settings, from_params, setting
from rclpy.node import Node
from rclpy.parameter import Parameter
from soft_robot_common import ConfigurationError, Param, declare_parameters, params_from_dataclass, undeclared_overrides

TABLE = [Param("gain", 1.0, "a live gain", min=0.0, max=2.0, live=True),
         Param("count", 3, "a fixed count", min=1, max=5),
         Param("mode", "e", "a live mode", choices=("e", "r"), live=True),
         ("legacy", "s", "an old-style row")]


@pytest.fixture(scope="module")
def context():
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    yield ctx
    rclpy.shutdown(context=ctx)


def _node(context, overrides=(), name="param_test"):
    node = Node(name, context=context, parameter_overrides=list(overrides))
    node.changes = []
    node.values = declare_parameters(node, TABLE, on_change=node.changes.append,
                                     validate=lambda v: "gain must be below count" if v["gain"] >= v["count"] else None)
    return node


@pytest.mark.system
def test_descriptors_carry_ranges_choices_and_read_only(context):
    node = _node(context)
    gain, count, mode, legacy = node.describe_parameters(["gain", "count", "mode", "legacy"])
    assert (gain.floating_point_range[0].from_value, gain.floating_point_range[0].to_value) == (0.0, 2.0)
    assert not gain.read_only and count.read_only and legacy.read_only
    assert (count.integer_range[0].from_value, count.integer_range[0].to_value) == (1, 5)
    assert "one of: e, r" in mode.description
    node.destroy_node()


@pytest.mark.system
def test_live_sets_are_checked_then_applied(context):
    node = _node(context)
    assert node.set_parameters([Parameter("gain", value=0.5)])[0].successful
    assert node.values["gain"] == 0.5 and node.changes == [{"gain": 0.5}]
    for bad in (Parameter("gain", value=2.5), Parameter("mode", value="x"), Parameter("count", value=2),
                Parameter("gain", value=float("nan"))):
        r = node.set_parameters([bad])[0]
        assert not r.successful and r.reason, bad.name
    assert node.values == {"gain": 0.5, "count": 3, "mode": "e", "legacy": "s"}
    assert len(node.changes) == 1
    node.destroy_node()


@pytest.mark.parametrize("override,words", [
    (Parameter("gain", value=3.0), "above its maximum 2.0"),
    (Parameter("gain", value=1), "floating-point number"),
    (Parameter("mode", value="zz"), "not one of"),
    (Parameter("count", value=0), "below its minimum 1"),
    (Parameter("gain", value=1.9), None),          # accepted alone ...
])
@pytest.mark.system
def test_start_up_values_are_checked(context, override, words):
    if words is None:
        node = _node(context, [override])
        assert node.values["gain"] == 1.9
        node.destroy_node()
        return
    with pytest.raises(ConfigurationError, match=words):
        _node(context, [override])


@pytest.mark.system
def test_cross_check_at_start_up(context):
    with pytest.raises(ConfigurationError, match="gain must be below count"):
        _node(context, [Parameter("gain", value=1.5), Parameter("count", value=1)])


@pytest.mark.system
def test_undeclared_overrides_name_the_closest_parameter(context):
    node = _node(context, [Parameter("gian", value=1.0), Parameter("zzz_unrelated", value=1)])
    assert undeclared_overrides(node) == [("gian", "gain"), ("zzz_unrelated", None)]
    node.destroy_node()


def test_rows_from_a_dataclass():
    @dataclasses.dataclass(frozen=True)
    class S(Settings):
        w: float = setting(2.0, "weight", min=0.0, unit="1/m", live=True)
        kind: str = setting("a", "kind", choices=("a", "b"))
        drag: float = setting(math.inf, "drag time; 0 = none", min=0.1, max=10.0, sentinel=(0.0, math.inf),
                              param="drag_time")
    w, kind, drag = params_from_dataclass(S)
    assert (w.name, w.default, w.min, w.max, w.live) == ("w", 2.0, 0.0, None, True)
    assert w.description == "weight [1/m]" and kind.choices == ("a", "b") and not kind.live
    assert w.problem(-1.0) and not w.problem(5.0)
    # the sentinel: the parameter shows 0 (allowed), the core holds inf
    assert (drag.name, drag.default, drag.min, drag.max) == ("drag_time", 0.0, 0.0, 10.0)
    assert drag.problem(0.0) is None and drag.problem(11.0)
    back = from_params(S, {"w": 3.0, "kind": "b", "drag_time": 0.0})
    assert (back.w, back.kind, back.drag) == (3.0, "b", math.inf)
    assert from_params(S, {"drag_time": 2.0}).drag == 2.0
    with pytest.raises(ValueError, match="drag=0.05 is below its minimum 0.1"):
        from_params(S, {"drag_time": 0.05})      # inside the descriptor's range, refused by the core


def test_topic_parameters_hold_valid_topic_names():
    row = Param("odom_topic", "frog/odom", "a topic")
    assert row.problem("frog/odom") is None and row.problem("/a/b") is None and row.problem("") is None
    for bad in ("bad name", "1abc", "a//b", "a/"):
        assert "is not a valid topic name" in row.problem(bad), bad
    assert "'x y'" in Param("topics", [""], "topics").problem(["/ok", "x y"])
    assert Param("odom_label", "odom", "not a topic").problem("bad name") is None
    assert "must name a frame" in Param("world_frame", "tank", "a frame").problem("")
