"""Declared parameters with ranges, one table per node, validated at start-up and when set.

A node keeps a table of :class:`Param` rows (or builds one from a settings dataclass with
:func:`params_from_dataclass`) and calls :func:`declare_parameters` in ``__init__``. The
same rows give the descriptor that ``ros2 param describe`` shows (type, description, range,
read-only), the start-up check, and the check of a ``ros2 param set`` on a live parameter,
so the range of a setting is written once.
"""

from __future__ import annotations

import dataclasses
import difflib
from typing import Any, Callable, Iterable

from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor, ParameterType,
                                SetParametersResult)
from frog_common.settings import describe, param_name, range_problem, to_param
from rclpy.exceptions import ParameterException

_TYPES = {bool: ParameterType.PARAMETER_BOOL, int: ParameterType.PARAMETER_INTEGER,
          float: ParameterType.PARAMETER_DOUBLE, str: ParameterType.PARAMETER_STRING}
_TYPE_WORDS = {bool: "a boolean (true/false)", int: "an integer", float: "a floating-point number (write 3.0, not 3)",
               str: "a string", list: "a list of strings"}
_INT_LIMIT = 2 ** 31 - 1      # an integer without a bound on one side: +-2147483647 (sizes, counts, seeds)
_FLOAT_LIMIT = 1e300          # likewise for doubles (finite, so the descriptor prints as a number)


def topic_name_problem(name: str) -> str | None:
    """Why ``name`` is not a valid (relative or absolute) ROS topic name, or None.

    The rule rcl applies when a publisher or subscription is created, checked before, so a
    bad name is a one-line configuration error rather than a traceback.
    """
    from rclpy.expand_topic_name import expand_topic_name
    from rclpy.validate_full_topic_name import validate_full_topic_name
    try:
        validate_full_topic_name(expand_topic_name(name, "node", "/"))
    except Exception as exc:          # rclpy raises ValueError or InvalidTopicNameException
        text = str(exc).splitlines()[0]
        text = text.split(", at /")[0]                          # drop the C source location
        text = text.replace(f"topic name {name!r} is invalid: ", "").replace("Invalid topic name: ", "")
        return f"is not a valid topic name ({text})"
    return None


def frame_name_problem(name: str) -> str | None:
    """Why ``name`` is not a usable tf frame id (empty, whitespace, a leading '/'), or None."""
    if not name:
        return "must name a frame (it is empty)"
    if any(c.isspace() for c in name):
        return "must not contain whitespace"
    if name.startswith("/"):
        return "must not start with '/' (tf2 frame ids are plain names)"
    return None


def _is_frame_param(name: str) -> bool:
    """Parameters named ``*_frame`` or ``frame_id`` hold a tf frame id."""
    leaf = name.rsplit(".", 1)[-1]
    return leaf.endswith("_frame") or leaf == "frame_id"


def _is_topic_param(name: str) -> bool:
    """Parameters named ``*_topic`` (one name) or ``topics``/``*_topics`` (a list) hold topic names."""
    leaf = name.rsplit(".", 1)[-1]
    return leaf.endswith("_topic") or leaf == "topic" or leaf == "topics" or leaf.endswith("_topics")


class ConfigurationError(ValueError):
    """A parameter value that makes the node's job impossible (fatal at start-up: exit 2)."""


@dataclasses.dataclass(frozen=True)
class Param:
    """One node parameter: name, default (its type is the parameter's type), description.

    ``min``/``max`` bound numbers (inclusive), ``choices`` lists the allowed strings, and
    ``live`` makes the parameter writable while the node runs (otherwise read-only). A
    parameter named ``*_topic`` (a string) or ``topics``/``*_topics`` (a list) must hold
    valid topic names (empty = none); one named ``*_frame`` or ``frame_id`` a non-empty frame
    id. ``ints_as_text`` lets a string parameter be given as
    an integer (``-p source:=0``: YAML reads 0 as a number); the node sees its text.
    The range check is frog_common's :func:`~frog_common.settings.range_problem`, the one
    the cores' settings use.
    """

    name: str
    default: Any
    description: str
    min: float | None = None
    max: float | None = None
    choices: tuple | None = None
    live: bool = False
    ints_as_text: bool = False     # a string that may also be given as an integer (a device index)
    special: tuple = ()            # values allowed outside the range (a sentinel such as 0 = none)

    @property
    def kind(self) -> type:
        return list if isinstance(self.default, (list, tuple)) else type(self.default)

    def problem(self, value) -> str | None:
        """Why ``value`` is not acceptable for this parameter, or None."""
        kind = self.kind
        ok_type = (isinstance(value, kind) and not (kind is int and isinstance(value, bool))
                   or kind is list and isinstance(value, (list, tuple)))
        if self.ints_as_text and isinstance(value, int) and not isinstance(value, bool):
            value, ok_type = str(value), True
        if not ok_type:
            return f"{self.name}={value!r} must be {_TYPE_WORDS[kind]}"
        if kind is int and not -_INT_LIMIT <= value <= _INT_LIMIT:
            return f"{self.name}={value!r} is outside +-{_INT_LIMIT}"
        if value not in self.special:
            problem = range_problem(self.name, value, self.min, self.max, self.choices)
            if problem:
                return problem
        if kind in (str, list) and _is_topic_param(self.name):
            for topic in ([value] if kind is str else value):
                problem = topic_name_problem(topic) if topic else None
                if problem:
                    return f"{self.name}={topic!r} {problem}"
        if kind is str and _is_frame_param(self.name):
            problem = frame_name_problem(value)
            if problem:
                return f"{self.name}={value!r} {problem}"
        return None

    def descriptor(self, full_name: str) -> ParameterDescriptor:
        kind = self.kind
        text = self.description
        if self.choices is not None:
            text += f" (one of: {', '.join(map(str, self.choices))})"
        d = ParameterDescriptor(name=full_name, type=_TYPES.get(kind, ParameterType.PARAMETER_STRING_ARRAY),
                                description=text, read_only=not self.live,
                                dynamic_typing=self.ints_as_text)
        if kind is int and (self.min is not None or self.max is not None):
            d.integer_range = [IntegerRange(
                from_value=int(self.min) if self.min is not None else -_INT_LIMIT,
                to_value=int(self.max) if self.max is not None else _INT_LIMIT, step=1)]
        elif kind is float and (self.min is not None or self.max is not None):
            d.floating_point_range = [FloatingPointRange(
                from_value=float(self.min) if self.min is not None else -_FLOAT_LIMIT,
                to_value=float(self.max) if self.max is not None else _FLOAT_LIMIT, step=0.0)]
        return d


def params_from_dataclass(cls, names: Iterable[str] | None = None, defaults=None) -> list[Param]:
    """:class:`Param` rows from a settings dataclass made with frog_common's ``setting()``.

    Each field gives one parameter (named by its ``param``, else the field): its default
    (``defaults``, an instance, overrides the class's), description with unit, range or
    choices, and ``live``. A sentinel's parameter value is allowed beside the range.
    ``names`` (field names) selects and orders fields. Build the instance back with
    ``frog_common.settings.from_params``.
    """
    fields = {f.name: f for f in dataclasses.fields(cls)}
    rows = []
    for name in (names if names is not None else fields):
        f = fields[name]
        md = f.metadata
        default = getattr(defaults, name) if defaults is not None else (
            f.default if f.default is not dataclasses.MISSING else f.default_factory())
        sentinel = md.get("sentinel")
        lo, hi = md.get("min"), md.get("max")
        if sentinel is not None and lo is not None and sentinel[0] < lo:
            lo = sentinel[0]            # the descriptor shows the sentinel as allowed
        rows.append(Param(param_name(f), to_param(f, default), describe(f), lo, hi, md.get("choices"),
                          bool(md.get("live", False)),
                          special=(sentinel[0],) if sentinel is not None else ()))
    return rows


def _as_param(row) -> Param:
    return row if isinstance(row, Param) else Param(*row)


def declare_parameters(node, table, prefix: str = "",
                       validate: Callable[[dict], str | None] | None = None,
                       on_change: Callable[[dict], None] | None = None) -> dict:
    """Declare ``table`` (Param rows, or ``(name, default, description)`` tuples) on ``node``.

    Returns ``{name: value}`` (without ``prefix``) as set by overrides or defaults; the dict
    is kept up to date when live parameters change. Raises :class:`ConfigurationError`
    naming the parameter when a start-up value has the wrong type, is out of range, is not
    among the choices, or fails ``validate(values)`` (which returns a reason or None).
    A set of a live parameter is checked the same way, refused with the reason if bad, and
    then passed to ``on_change({name: value, ...})``.
    """
    rows = [_as_param(r) for r in table]
    values: dict = {}
    for row in rows:
        full = prefix + row.name
        try:
            node.declare_parameter(full, row.default, row.descriptor(full))
        except ParameterException as exc:
            given = node._parameter_overrides.get(full)
            value = given.value if given is not None else None
            problem = row.problem(value)
            raise ConfigurationError(prefix + problem if problem else f"{full}: {exc}") from None
        value = node.get_parameter(full).value
        if isinstance(value, tuple):
            value = list(value)
        if row.ints_as_text and isinstance(value, int) and not isinstance(value, bool):
            value = str(value)
        problem = row.problem(value)
        if problem:
            raise ConfigurationError(prefix + problem)
        values[row.name] = value
    if validate is not None:
        reason = validate(dict(values))
        if reason:
            raise ConfigurationError(reason)

    by_full = {prefix + r.name: r for r in rows}

    def check(params) -> SetParametersResult:
        candidate = dict(values)
        mine = False
        for p in params:
            row = by_full.get(p.name)
            if row is None:
                continue
            mine = True
            value = list(p.value) if isinstance(p.value, tuple) else p.value
            if row.ints_as_text and isinstance(value, int) and not isinstance(value, bool):
                value = str(value)
            problem = row.problem(value)
            if problem:
                return SetParametersResult(successful=False, reason=prefix + problem)
            candidate[row.name] = value
        if mine and validate is not None:
            reason = validate(candidate)
            if reason:
                return SetParametersResult(successful=False, reason=reason)
        return SetParametersResult(successful=True)

    def apply(params) -> None:
        changed = {}
        for p in params:
            row = by_full.get(p.name)
            if row is not None:
                changed[row.name] = list(p.value) if isinstance(p.value, tuple) else p.value
        if not changed:
            return
        values.update(changed)
        node.get_logger().info("parameters changed: " + ", ".join(f"{prefix}{k}={v!r}" for k, v in changed.items()))
        if on_change is not None:
            on_change(changed)

    if any(r.live for r in rows):
        node.add_on_set_parameters_callback(check)
        node.add_post_set_parameters_callback(apply)
    return values


def undeclared_overrides(node) -> list[tuple[str, str | None]]:
    """``[(name, closest declared name or None)]`` for overrides the node never declared."""
    declared = set(node._parameters)
    out = []
    for name in sorted(node._parameter_overrides):
        if name not in declared:
            close = difflib.get_close_matches(name, sorted(declared), n=1, cutoff=0.5)
            out.append((name, close[0] if close else None))
    return out
