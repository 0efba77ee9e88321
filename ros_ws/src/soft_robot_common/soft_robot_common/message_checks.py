"""One rule for incoming messages, requests and goals: finite numbers, a stamp, sane sizes.

Every float in a message (nested messages and arrays included) must be finite; a message
with a ``header`` must be stamped (a zero stamp is refused once the node's clock has passed
1 s: at the very start of simulated time 0 is a real time); arrays hold at most
``max_items`` elements (byte data such as image pixels excepted). :func:`message_problem`
returns the first violation as a short text
naming the field (``"pose.pose.position.x is nan (not finite)"``), or None. It works on any generated
ROS message (duck-typed on ``get_fields_and_field_types``), so it needs no rclpy.

The stamp rule is for state estimates (odometry, poses): a command (a primitive, a limb
pulse, a setpoint) with a zero stamp means "now", as ``ros2 topic pub`` sends it, so command
callbacks pass ``stamped=False``.
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
                return f"{path} is {value!r} (not finite)"
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
                        return f"{path}[{i}] is {float(item)!r} (not finite)"
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


class MessageGate:
    """Applies :func:`message_problem` to a node's inputs and logs each refusal.

    ``gate.refused("frog/primitive", msg)`` is True (and logs ``refused frog/primitive:
    <field> is nan``) when ``msg`` breaks the rule. Logs are limited to one a second per
    input and problem (a flood of one bad value logs once a second; a different field or
    value is logged at once), all counted in :attr:`counts` (``{input: refusals}``).
    """

    def __init__(self, node, max_items: int = MAX_ITEMS):
        self.node = node
        self.max_items = max_items
        self.counts: dict = {}
        self._last_log: dict = {}

    def problem(self, msg, stamped: bool = True) -> str | None:
        now = self.node.get_clock().now().nanoseconds if stamped else None
        return message_problem(msg, now, stamped, self.max_items)

    def refused(self, what: str, msg, stamped: bool = True) -> bool:
        problem = self.problem(msg, stamped)
        if problem is None:
            return False
        self.refuse(what, problem)
        return True

    def refuse(self, what: str, problem: str) -> None:
        """Count and log (rate-limited per input and problem) a refusal found by the caller."""
        if self.should_log(what, problem):
            self.node.get_logger().warn(f"refused {what}: {problem}")

    def should_log(self, what: str, problem: str) -> bool:
        """Count a refusal; True if it should be logged now (once a second per input and problem)."""
        import time
        self.counts[what] = self.counts.get(what, 0) + 1
        now = time.monotonic()
        if len(self._last_log) > 1000:
            self._last_log.clear()
        if now - self._last_log.get((what, problem), -1e9) < 1.0:
            return False
        self._last_log[(what, problem)] = now
        return True
