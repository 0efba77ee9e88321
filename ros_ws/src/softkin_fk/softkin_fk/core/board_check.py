"""Pre-flight of a Marlin board before the finger moves: handshake, position, limits, zero.

Runs over any line transport with ``write(bytes)`` and ``readline() -> bytes`` (pyserial
with a read timeout; no ROS): the start banner is drained, then

* ``M115`` must be answered with ``ok`` (and normally ``FIRMWARE_NAME:``): a Marlin board at
  this baud rate is there;
* ``M114`` must report ``X:.. Y:.. Z:..``: the position is known;
* ``M211``: with soft endstops on, their range must hold the driver's pull limits (or the
  board would cut moves short); off or unknown: the driver's limits are the only ones;
* the zero: ``declared`` (the cables are at rest now; the driver declares it with ``G92``)
  or ``home`` (``G28``, for a board with endstops; must end with ``ok``).
"""
from __future__ import annotations

import re
import time
from dataclasses import dataclass

_AXIS = re.compile(r"([XYZE]):\s*(-?\d+(?:\.\d*)?)")


@dataclass
class BoardCheck:
    name: str
    ok: bool
    message: str


def _exchange(io, command: str, timeout: float):
    """Send ``command``; the reply lines up to ``ok`` and whether ``ok`` came within ``timeout``."""
    io.write((command + "\n").encode())
    lines = []
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        raw = io.readline()
        if not raw:
            continue
        line = raw.decode("ascii", "replace").strip()
        if line.startswith("ok"):
            return lines, True
        if line:
            lines.append(line)
    return lines, False


def check_board(io, port: str, axes=("X", "Y", "Z"), pull_range_units=(0.0, 0.68), zero: str = "declared",
                timeout: float = 3.0, banner_s: float = 2.5, home_timeout: float = 60.0) -> list[BoardCheck]:
    """The pre-flight checks in order; stops at the first one the others depend on (no answer)."""
    end = time.monotonic() + banner_s
    while time.monotonic() < end:            # a real Arduino resets on open: drain its banner
        if not io.readline() and time.monotonic() > end - banner_s / 2:
            break
    checks = []
    lines, ok = _exchange(io, "M115", timeout)
    if not ok:
        heard = f"; it said {lines[-1]!r}" if lines else ", nothing at all"
        checks.append(BoardCheck("handshake", False, f"the board on {port} did not answer M115 with ok within "
                                                     f"{timeout:g} s{heard} (a Marlin board, at 115200 baud?)"))
        return checks
    name = next((ln.split("FIRMWARE_NAME:")[1].split(" SOURCE_CODE_URL")[0] for ln in lines if "FIRMWARE_NAME:" in ln),
                None)
    checks.append(BoardCheck("handshake", True, f"{port}: {name or 'a board that answers ok (no FIRMWARE_NAME)'}"))
    lines, ok = _exchange(io, "M114", timeout)
    report = next((ln for ln in lines if _AXIS.search(ln)), None)
    if not ok or report is None:
        checks.append(BoardCheck("position", False, f"the board on {port} gave no position on M114 "
                                                    f"(reply {lines or 'none'})"))
        return checks
    pos = {a: float(v) for a, v in _AXIS.findall(report.split("Count")[0])}
    checks.append(BoardCheck("position", True, "position " + " ".join(f"{a}{pos.get(a, float('nan')):.3f}"
                                                                      for a in axes)))
    lines, ok = _exchange(io, "M211", timeout)
    text = next((ln for ln in lines if "Soft endstops" in ln), None)
    lo, hi = pull_range_units
    if text is None or "Off" in text:
        checks.append(BoardCheck("limits", True, f"board soft endstops {'off' if text else 'not reported'}; the "
                                                 f"driver's limits apply: {lo:g}..{hi:g} axis units of pull"))
    else:
        parts = text.split("Max:")
        mins = dict(_AXIS.findall(parts[0].split("Min:")[-1])) if "Min:" in parts[0] else {}
        maxs = dict(_AXIS.findall(parts[1])) if len(parts) > 1 else {}
        narrow = [a for a in axes if float(mins.get(a, lo)) > lo + 1e-9 or float(maxs.get(a, hi)) < hi - 1e-9]
        checks.append(BoardCheck("limits", not narrow,
                                 f"board soft endstops on ({text.split('Soft endstops:')[1].strip()})"
                                 + (f": axes {', '.join(narrow)} narrower than the driver's {lo:g}..{hi:g}; "
                                    "widen them (M211/M208) or lower max_pull" if narrow else
                                    f"; they hold the driver's {lo:g}..{hi:g}")))
    if zero == "home":
        lines, ok = _exchange(io, "G28", home_timeout)
        checks.append(BoardCheck("zero", ok, "homed (G28)" if ok else f"G28 not finished within {home_timeout:g} s "
                                                                      f"({lines[-1] if lines else 'no reply'})"))
    else:
        checks.append(BoardCheck("zero", True, "declared zero: the cables are at rest now (the driver sends G92)"))
    return checks
