"""The robot's serial line protocol, both directions (authors' firmware; DESIGN.md).

To the robot (host -> relay), ASCII lines ending ``\\n``:

- ``p <ms>``: set the heating pulse length [ms] (integer);
- ``h <id> [<id> ...]``: heat the listed limbs for one pulse (FL 0, FR 1, BL 2, BR 3),
  ids separated by single spaces, e.g. ``h 1 0``.

From the relay (relay -> host), lines ending ``\\r\\n`` (``\\n`` alone is accepted): the
robot's messages carry the relay's ``Central: `` prefix (9 characters). The authors' code
tests ``line[0:4] == "Cent"`` and the character at index 9:

- ``Central: Q <a> <b> <c> <d>``: an IMU orientation quaternion, four decimal numbers
  separated by spaces (commas or semicolons are accepted too), in the order given by
  ``order`` (``"wxyz"`` by default);
- ``Central: EMERGENCY...``: the robot reports a fault;
- any other line is returned as text to be logged.

Decoding never raises: every malformed input yields a :class:`DecodeError` whose
:class:`ErrorKind` names the problem.
"""

from __future__ import annotations

import enum
import math
import re
from dataclasses import dataclass

from frog_common.primitives import LIMB_NAMES

RELAY_PREFIX = "Central: "          # 9 characters; the payload starts at index 9
QUATERNION_ORDERS = ("wxyz", "xyzw")
MAX_PULSE_MS = 1000
DEFAULT_MAX_LINE_BYTES = 256        # longest line either side ever produces is < 80 bytes


class ErrorKind(enum.Enum):
    """Why a line could not be decoded."""

    NOT_TEXT = "not_text"                   # not valid UTF-8
    TOO_LONG = "too_long"                   # longer than the framer's limit (discarded)
    UNKNOWN_COMMAND = "unknown_command"     # host line that is neither p nor h
    BAD_ARGUMENT = "bad_argument"           # p/h with a missing, malformed or out-of-range argument
    BAD_QUATERNION = "bad_quaternion"       # Q line without four finite numbers of unit norm


@dataclass(frozen=True)
class DecodeError:
    """A line that could not be decoded; ``excerpt`` is a printable, shortened copy."""

    kind: ErrorKind
    message: str
    excerpt: str = ""

    def __str__(self) -> str:
        return f"{self.kind.value}: {self.message}" + (f" in {self.excerpt}" if self.excerpt else "")


# -- host -> robot ----------------------------------------------------------------------
@dataclass(frozen=True)
class SetPulse:
    """``p <ms>``."""

    ms: int


@dataclass(frozen=True)
class Heat:
    """``h <ids>``: limb ids in the order written."""

    limbs: tuple[int, ...]


@dataclass(frozen=True)
class Blank:
    """An empty line (ignored by the firmware)."""


# -- relay -> host ----------------------------------------------------------------------
@dataclass(frozen=True)
class Quaternion:
    """Unit orientation quaternion reported by the robot's IMU; ``norm`` as received."""

    w: float
    x: float
    y: float
    z: float
    norm: float = 1.0


@dataclass(frozen=True)
class Emergency:
    """The robot reported a fault (``Central: EMERGENCY``)."""

    text: str


@dataclass(frozen=True)
class RelayText:
    """Any other line: ``from_robot`` when it carries the ``Cent`` prefix."""

    text: str
    from_robot: bool


def excerpt(raw: bytes | str, limit: int = 60) -> str:
    """Printable, shortened ``repr`` of a line for logs."""
    r = repr(raw[:limit])
    return r + (f"...(+{len(raw) - limit})" if len(raw) > limit else "")


def encode_set_pulse(ms: int) -> bytes:
    """``b"p 80\\n"``; ``ms`` must be an integer in 1-1000.

    Raises
    ------
    ValueError
        For a pulse length out of range.
    """
    if not (isinstance(ms, int) and not isinstance(ms, bool) and 1 <= ms <= MAX_PULSE_MS):
        raise ValueError(f"pulse length {ms!r} ms must be an integer in 1-{MAX_PULSE_MS}")
    return f"p {ms}\n".encode("ascii")


def encode_heat(limbs) -> bytes:
    """``b"h 1 0\\n"`` for limbs ``(1, 0)``: ids 0-3, distinct, at least one.

    Raises
    ------
    ValueError
        For an empty list, repeated ids or an id outside 0-3.
    """
    limbs = tuple(limbs)
    if not limbs or len(set(limbs)) != len(limbs) or any(i not in range(len(LIMB_NAMES)) for i in limbs):
        raise ValueError(f"limb ids {list(limbs)} must be distinct, in 0-3, at least one")
    return ("h " + " ".join(str(i) for i in limbs) + "\n").encode("ascii")


def _text(raw: bytes) -> str | DecodeError:
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        return DecodeError(ErrorKind.NOT_TEXT, f"byte {exc.start} is not UTF-8", excerpt(raw))
    return text.rstrip("\r\n")


def decode_command(raw: bytes) -> SetPulse | Heat | Blank | DecodeError:
    """Parse one host line (without or with its newline) as the firmware does.

    Whitespace between tokens may be repeated (the authors' code writes ``h  2 3``).
    """
    text = _text(raw)
    if isinstance(text, DecodeError):
        return text
    tokens = text.split()
    if not tokens:
        return Blank()
    cmd, args = tokens[0], tokens[1:]
    if cmd == "p":
        if len(args) != 1 or not args[0].isdigit() or not 1 <= int(args[0]) <= MAX_PULSE_MS:
            return DecodeError(ErrorKind.BAD_ARGUMENT,
                               f"p needs one integer pulse length in 1-{MAX_PULSE_MS} ms", excerpt(text))
        return SetPulse(int(args[0]))
    if cmd == "h":
        if not args:
            return DecodeError(ErrorKind.BAD_ARGUMENT, "h without limb ids", excerpt(text))
        if any(a not in ("0", "1", "2", "3") for a in args) or len(set(args)) != len(args):
            return DecodeError(ErrorKind.BAD_ARGUMENT, "h limb ids must be distinct digits 0-3",
                               excerpt(text))
        return Heat(tuple(int(a) for a in args))
    return DecodeError(ErrorKind.UNKNOWN_COMMAND, f"unknown command {cmd[:10]!r}", excerpt(text))


_NUMBER = re.compile(r"[-+]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][-+]?\d+)?")
_SEPARATORS = re.compile(r"[\s,;]+")


def decode_relay_line(raw: bytes, order: str = "wxyz", norm_tolerance: float = 0.1
                      ) -> Quaternion | Emergency | RelayText | DecodeError:
    """Parse one relay line (without or with its ``\\r\\n``).

    Parameters
    ----------
    raw : bytes
        The line.
    order : {"wxyz", "xyzw"}
        Order of the four numbers after ``Q``.
    norm_tolerance : float
        A quaternion whose norm differs from 1 by more than this is refused (a garbled
        line); within it the quaternion is normalised.
    """
    text = _text(raw)
    if isinstance(text, DecodeError):
        return text
    if not text.startswith("Cent") or len(text) <= 9:
        return RelayText(text, from_robot=text.startswith("Cent"))
    if text[9] == "Q":
        return _quaternion(text, order, norm_tolerance)
    if text[9:18] == "EMERGENCY":
        return Emergency(text)
    return RelayText(text, from_robot=True)


def _quaternion(text: str, order: str, tol: float) -> Quaternion | DecodeError:
    body = text[10:].strip().lstrip(":=").strip()
    tokens = [t for t in _SEPARATORS.split(body) if t]
    if len(tokens) != 4:
        return DecodeError(ErrorKind.BAD_QUATERNION,
                           f"expected four numbers after Q, got {len(tokens)} token(s)", excerpt(text))
    for i, token in enumerate(tokens):
        if not _NUMBER.fullmatch(token):
            finite = token.lower().lstrip("+-") not in ("nan", "inf", "infinity")
            return DecodeError(ErrorKind.BAD_QUATERNION,
                               f"number {i + 1} after Q is {'not a number' if finite else 'non-finite'}: "
                               f"{token[:16]!r}", excerpt(text))
    values = [float(t) for t in tokens]
    if not all(math.isfinite(v) for v in values):
        return DecodeError(ErrorKind.BAD_QUATERNION, "non-finite number", excerpt(text))
    if order == "wxyz":
        w, x, y, z = values
    elif order == "xyzw":
        x, y, z, w = values
    else:
        return DecodeError(ErrorKind.BAD_QUATERNION, f"unknown order {order!r}", "")
    norm = math.sqrt(w * w + x * x + y * y + z * z)
    if not abs(norm - 1.0) <= tol:
        return DecodeError(ErrorKind.BAD_QUATERNION,
                           f"norm {norm:.4g} is not 1 +- {tol:g}", excerpt(text))
    return Quaternion(w / norm, x / norm, y / norm, z / norm, norm)


def encode_quaternion(w: float, x: float, y: float, z: float, order: str = "wxyz") -> bytes:
    """The line the robot emulator writes: ``b"Central: Q 0.9239 0.0000 0.0000 0.3827\\r\\n"``.

    Four numbers with 4 decimals, single spaces, in ``order``.
    """
    values = {"wxyz": (w, x, y, z), "xyzw": (x, y, z, w)}[order]
    return (RELAY_PREFIX + "Q " + " ".join(f"{v:.4f}" for v in values) + "\r\n").encode("ascii")


def encode_emergency() -> bytes:
    """``b"Central: EMERGENCY\\r\\n"``."""
    return (RELAY_PREFIX + "EMERGENCY\r\n").encode("ascii")


class LineFramer:
    """Split a byte stream into lines; keep a partial line; discard over-long ones.

    ``feed`` returns complete lines (``bytes`` without the ``\\n``; a trailing ``\\r``
    stays for the decoder to strip) and one :class:`DecodeError` (TOO_LONG) per line that
    exceeded ``max_line_bytes``; the rest of such a line, up to its newline, is dropped.
    """

    def __init__(self, max_line_bytes: int = DEFAULT_MAX_LINE_BYTES):
        if max_line_bytes < 1:
            raise ValueError(f"max_line_bytes {max_line_bytes} must be >= 1")
        self.max_line_bytes = max_line_bytes
        self._buf = bytearray()
        self._skipping = 0          # > 0: bytes dropped so far of an over-long line
        self._head = b""            # start of that line, for the error message

    @property
    def pending(self) -> int:
        """Bytes of the partial line kept so far."""
        return len(self._buf)

    def reset(self) -> None:
        """Forget any partial line (after a reconnect: its start belonged to another link)."""
        self._buf.clear()
        self._skipping = 0

    def feed(self, data: bytes) -> list[bytes | DecodeError]:
        out: list[bytes | DecodeError] = []
        start = 0
        n = len(data)
        while start < n:
            nl = data.find(b"\n", start)
            end = n if nl < 0 else nl
            chunk = data[start:end]
            if self._skipping:
                self._skipping += len(chunk)
            elif len(self._buf) + len(chunk) > self.max_line_bytes:
                self._skipping = len(self._buf) + len(chunk)
                self._head = bytes(self._buf[:40]) + chunk[:max(0, 40 - len(self._buf))]
                self._buf.clear()
            else:
                self._buf += chunk
            if nl < 0:
                break
            if self._skipping:
                out.append(DecodeError(ErrorKind.TOO_LONG, f"line of {self._skipping} bytes exceeds "
                                       f"{self.max_line_bytes}; discarded", excerpt(self._head, 40)))
                self._skipping = 0
            else:
                out.append(bytes(self._buf))
                self._buf.clear()
            start = nl + 1
        return out
