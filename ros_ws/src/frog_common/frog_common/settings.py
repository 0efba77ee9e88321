"""One way to declare a setting of a core, and one check of its range.

A core's settings class is a frozen dataclass deriving from :class:`Settings`, each field
made by :func:`setting` (default, description, unit, ``min``/``max`` or ``choices``, and
whether it may change while a node runs). Building an instance checks every field
(:func:`check`), then the class's own :meth:`Settings.cross_check` of relations between
fields. The ROS layer (soft_robot_common ``params_from_dataclass``) declares node
parameters from the same fields and checks a parameter with the same :func:`range_problem`,
so a range is written once and checked in one place.

A node parameter may stand for a value ROS cannot hold: ``sentinel=(0.0, math.inf)`` says
that the parameter value 0.0 means ``inf`` in the core (:func:`to_core`, :func:`to_param`).
``param`` names the node parameter where it differs from the field (kept for compatibility).
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from typing import Any


def setting(default: Any, description: str, *, min: float | None = None, max: float | None = None,
            choices=None, unit: str = "", live: bool = False, sentinel: tuple | None = None,
            param: str | None = None, flags: tuple = ()) -> Any:
    """A dataclass field holding one setting (``min``/``max`` inclusive; ``flags``: CLI aliases)."""
    md = {"description": description, "min": min, "max": max, "unit": unit, "live": live,
          "choices": tuple(choices) if choices is not None else None, "sentinel": sentinel,
          "param": param, "flags": tuple(flags)}
    if isinstance(default, (list, tuple)):
        return dataclasses.field(default_factory=lambda: tuple(default), metadata=md)
    return dataclasses.field(default=default, metadata=md)


def range_problem(name: str, value, min=None, max=None, choices=None) -> str | None:
    """Why ``value`` is outside ``[min, max]``, not finite, or not among ``choices``; or None."""
    if isinstance(value, numbers.Real) and not isinstance(value, bool):
        if not math.isfinite(value):
            return f"{name}={value!r} must be finite"
        if min is not None and value < min:
            return f"{name}={value!r} is below its minimum {min!r}"
        if max is not None and value > max:
            return f"{name}={value!r} is above its maximum {max!r}"
    if choices is not None and value not in choices:
        return f"{name}={value!r} is not one of {', '.join(map(repr, choices))}"
    return None


def _kind(f: dataclasses.Field) -> type:
    default = f.default if f.default is not dataclasses.MISSING else f.default_factory()
    return tuple if isinstance(default, (list, tuple)) else type(default)


def _type_problem(name: str, value, kind: type) -> str | None:
    ok = {bool: lambda v: isinstance(v, bool) or type(v).__name__ in ("bool_", "bool"),   # numpy bools too
          int: lambda v: isinstance(v, numbers.Integral) and not isinstance(v, bool),
          float: lambda v: isinstance(v, numbers.Real) and not isinstance(v, bool),
          str: lambda v: isinstance(v, str),
          tuple: lambda v: isinstance(v, (list, tuple))}.get(kind, lambda v: True)
    return None if ok(value) else f"{name}={value!r} must be {kind.__name__}"


def field_problem(f: dataclasses.Field, value) -> str | None:
    """Why ``value`` does not fit the setting ``f`` (type, range, choices), or None."""
    md = f.metadata
    problem = _type_problem(f.name, value, _kind(f))
    if problem:
        return problem
    sentinel = md.get("sentinel")
    if sentinel is not None and value == sentinel[1]:
        return None
    return range_problem(f.name, value, md.get("min"), md.get("max"), md.get("choices"))


def check(settings) -> str | None:
    """Why an instance's values do not fit their settings, then its cross-check; or None."""
    for f in dataclasses.fields(settings):
        if "description" in f.metadata:
            problem = field_problem(f, getattr(settings, f.name))
            if problem:
                return problem
    cross = getattr(settings, "cross_check", None)
    return cross() if cross is not None else None


class Settings:
    """Base of a frozen settings dataclass: construction raises ValueError on a bad value."""

    def __post_init__(self):
        reason = check(self)
        if reason:
            raise ValueError(reason)

    def cross_check(self) -> str | None:
        """Why the values, each in range, do not go together; or None (override)."""
        return None

    def replace(self, **changes):
        """A checked copy with some fields changed."""
        return dataclasses.replace(self, **changes)

    def as_dict(self) -> dict:
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}


def describe(f: dataclasses.Field) -> str:
    """The field's description with its unit: ``"... [m]"``."""
    unit = f.metadata.get("unit", "")
    text = f.metadata.get("description", f.name)
    return f"{text} [{unit}]" if unit and unit != "-" else text


def param_name(f: dataclasses.Field) -> str:
    """The node parameter of the field (its own name unless ``param`` says otherwise)."""
    return f.metadata.get("param") or f.name


def to_param(f: dataclasses.Field, value):
    """The core value as a node parameter (a sentinel's core value becomes its parameter value)."""
    sentinel = f.metadata.get("sentinel")
    if sentinel is not None and value == sentinel[1]:
        return sentinel[0]
    return list(value) if isinstance(value, tuple) else value


def to_core(f: dataclasses.Field, value):
    """A node parameter's value as the core's (the sentinel's parameter value becomes its core value)."""
    sentinel = f.metadata.get("sentinel")
    if sentinel is not None and value == sentinel[0]:
        return sentinel[1]
    return tuple(value) if isinstance(value, list) else value


def from_params(cls, values: dict, base=None, **overrides):
    """An instance of ``cls`` from node parameters ``{param name: value}`` (missing: ``base`` or defaults)."""
    kw = {}
    for f in dataclasses.fields(cls):
        name = param_name(f)
        if name in values:
            kw[f.name] = to_core(f, values[name])
        elif base is not None:
            kw[f.name] = getattr(base, f.name)
    kw.update(overrides)
    return cls(**kw)
