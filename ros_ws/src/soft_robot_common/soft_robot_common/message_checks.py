"""One rule for incoming messages, requests and goals: finite numbers, a stamp, sane sizes.

Every float in a message (nested messages and arrays included) must be finite; a message
with a ``header`` must be stamped (a zero stamp is refused once the node's clock has passed
1 s: at the very start of simulated time 0 is a real time); arrays hold at most
``max_items`` elements (byte data such as image pixels excepted). :func:`message_problem`
returns the first violation as a short text
naming the field (``"pose.pose.position.x is nan"``), or None. It works on any generated
ROS message (duck-typed on ``get_fields_and_field_types``), so it needs no rclpy.
"""

from __future__ import annotations

import math

MAX_ITEMS = 100_000            # default bound of any array in an incoming message
_UNSTAMPED_AFTER_NS = 1_000_000_000


def _is_message(value) -> bool:
    return hasattr(type(value), "get_fields_and_field_types")


def nonfinite_field(msg, prefix: str = "", max_items: int = MAX_ITEMS) -> str | None:
    """The first float field of ``msg`` that is not finite, or array longer than ``max_items``."""
    for name in type(msg).get_fields_and_field_types():
        value = getattr(msg, name)
        path = f"{prefix}{name}"
        if isinstance(value, float):
            if not math.isfinite(value):
                return f"{path} is {value!r}"
        elif _is_message(value):
            problem = nonfinite_field(value, path + ".", max_items)
            if problem:
                return problem
        elif isinstance(value, (bytes, str)):
            if len(value) > max_items * 10:
                return f"{path} has {len(value)} characters (at most {max_items * 10})"
        elif hasattr(value, "__len__") and not isinstance(value, dict):
            dtype = getattr(value, "dtype", None)
            if getattr(value, "typecode", None) in ("b", "B") or dtype is not None and dtype.itemsize == 1:
                continue           # byte data (images, blobs): the message type bounds it
            if len(value) > max_items:
                return f"{path} has {len(value)} elements (at most {max_items})"
            for i, item in enumerate(value):
                if isinstance(item, float) or hasattr(item, "dtype") and item.dtype.kind == "f":
                    if not math.isfinite(item):
                        return f"{path}[{i}] is {float(item)!r}"
                elif _is_message(item):
                    problem = nonfinite_field(item, f"{path}[{i}].", max_items)
                    if problem:
                        return problem
                else:
                    break          # integers, strings, bytes: nothing to check per item
    return None


def stamp_problem(msg, now_ns: int | None) -> str | None:
    """``"header.stamp is zero (unstamped)"`` for a zero stamp once ``now_ns`` is past 1 s."""
    header = getattr(msg, "header", None)
    if header is None or not hasattr(header, "stamp"):
        return None
    if header.stamp.sec == 0 and header.stamp.nanosec == 0 and (now_ns is None or now_ns > _UNSTAMPED_AFTER_NS):
        return "header.stamp is zero (unstamped)"
    return None


def message_problem(msg, now_ns: int | None = None, stamped: bool = True, max_items: int = MAX_ITEMS) -> str | None:
    """Why ``msg`` must be refused (first problem, naming the field), or None.

    ``now_ns`` is the receiving node's clock (``node.get_clock().now().nanoseconds``);
    ``stamped=False`` skips the stamp rule (requests, goals, unstamped types).
    """
    problem = nonfinite_field(msg, "", max_items)
    if problem is None and stamped:
        problem = stamp_problem(msg, now_ns)
    return problem
