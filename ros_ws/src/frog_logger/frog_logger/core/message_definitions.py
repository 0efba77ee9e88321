"""Full ``ros2msg`` message definitions for MCAP schemas, built from installed .msg files.

MCAP readers (Foxglove, ``mcap_ros2``) decode a ROS 2 CDR message with a schema holding
the message's own definition followed by every type it depends on, each after a line of
80 ``=`` and a ``MSG: pkg/Type`` line (the format rosbag2 writes). The .msg files are
found under ``<prefix>/share/<pkg>/msg/`` of the ament prefixes, so no rclpy is needed.
"""

from __future__ import annotations

import os
import re
from pathlib import Path
from typing import Callable, Iterable, Optional

__all__ = [
    "MessageDefinitionError",
    "PRIMITIVE_TYPES",
    "full_message_definition",
    "find_msg_file",
    "normalize_type_name",
]

# Field types that need no further definition (ROS 2 .msg primitives).
PRIMITIVE_TYPES = frozenset({
    "bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
    "int32", "uint32", "int64", "uint64", "string", "wstring",
    "time", "duration",  # ROS 1 built-ins, accepted for foreign definitions
})

SEPARATOR = "=" * 80

_TYPE_RE = re.compile(r"^([A-Za-z][A-Za-z0-9_]*)/(?:msg/)?([A-Za-z][A-Za-z0-9_]*)$")


class MessageDefinitionError(LookupError):
    """A message type or one of its dependencies has no readable .msg file."""


def normalize_type_name(type_name: str) -> tuple[str, str]:
    """Split ``pkg/msg/Type`` or ``pkg/Type`` into ``(pkg, Type)``.

    Raises
    ------
    ValueError
        If the name is not of either form (e.g. a service or action type).
    """
    m = _TYPE_RE.match(type_name.strip())
    if not m:
        raise ValueError(
            f"message type {type_name!r} is not of the form 'pkg/msg/Type' or 'pkg/Type'")
    return m.group(1), m.group(2)


def _ament_prefixes() -> list[str]:
    return [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]


def find_msg_file(package: str, type_name: str,
                  prefixes: Optional[Iterable[str]] = None) -> Optional[Path]:
    """Return the first ``share/<package>/msg/<type_name>.msg`` under the ament prefixes."""
    for prefix in (_ament_prefixes() if prefixes is None else prefixes):
        path = Path(prefix, "share", package, "msg", f"{type_name}.msg")
        if path.is_file():
            return path
    return None


def _field_base_type(line: str, package: str) -> Optional[str]:
    """Base type ``pkg/Type`` of a field line, or None for comments, constants, primitives."""
    code = line.split("#", 1)[0].strip()
    if not code:
        return None
    parts = code.split()
    if len(parts) < 2:
        return None
    if "=" in parts[1] or (len(parts) > 2 and parts[2].startswith("=")):
        return None  # constant: "uint8 ID_A=0"
    base = re.sub(r"\[.*\]$", "", parts[0])      # drop array suffix
    base = re.sub(r"<=\d+$", "", base)            # bounded string<=N
    if base in PRIMITIVE_TYPES:
        return None
    if base == "Header":
        return "std_msgs/Header"
    if "/" not in base:
        return f"{package}/{base}"
    pkg, name = normalize_type_name(base)
    return f"{pkg}/{name}"


def full_message_definition(
    type_name: str,
    read_msg: Optional[Callable[[str, str], Optional[str]]] = None,
) -> str:
    """Concatenated ``ros2msg`` definition of a message type and all its dependencies.

    Parameters
    ----------
    type_name : str
        ``pkg/msg/Type`` (as reported by the ROS graph) or ``pkg/Type``.
    read_msg : callable, optional
        ``read_msg(pkg, Type) -> text or None``; defaults to reading .msg files from the
        ament prefixes in ``AMENT_PREFIX_PATH``.

    Returns
    -------
    str
        The definition text for an MCAP schema with encoding ``ros2msg``.

    Raises
    ------
    MessageDefinitionError
        If the type or any dependency cannot be found.
    """
    if read_msg is None:
        def read_msg(pkg: str, name: str) -> Optional[str]:
            path = find_msg_file(pkg, name)
            return path.read_text() if path else None

    root_pkg, root_name = normalize_type_name(type_name)
    root_text = read_msg(root_pkg, root_name)
    if root_text is None:
        raise MessageDefinitionError(
            f"no definition found for message type {type_name!r} "
            f"(looked for share/{root_pkg}/msg/{root_name}.msg under AMENT_PREFIX_PATH)")

    sections = [root_text.rstrip("\n")]
    seen = {f"{root_pkg}/{root_name}"}
    queue = [(root_pkg, root_text)]
    while queue:
        pkg, text = queue.pop(0)
        for line in text.splitlines():
            dep = _field_base_type(line, pkg)
            if dep is None or dep in seen:
                continue
            seen.add(dep)
            dep_pkg, dep_name = dep.split("/")
            dep_text = read_msg(dep_pkg, dep_name)
            if dep_text is None:
                raise MessageDefinitionError(
                    f"message type {type_name!r} depends on {dep!r}, whose definition "
                    f"was not found (share/{dep_pkg}/msg/{dep_name}.msg)")
            sections.append(f"{SEPARATOR}\nMSG: {dep}\n{dep_text.rstrip(chr(10))}")
            queue.append((dep_pkg, dep_text))
    return "\n".join(sections) + "\n"
