"""Marlin's serial G-code protocol as far as the finger's stepper driver uses it (no I/O here).

Host -> board lines carry a line number and a checksum, ``N<n> <command>*<checksum>``, the
checksum being the XOR of all bytes before ``*``. The board answers every accepted command
with ``ok``; a line with a wrong number or checksum gets ``Error:...`` and ``Resend: <n>``
(the first line to send again; Marlin 2 sends no ``ok`` with it, Marlin 1 did). ``M110 N<n>``
sets the line number; ``M114`` reports ``X:.. Y:.. Z:.. E:.. Count X:.. Y:.. Z:..`` (the
planned position in axis units, then the steppers' step counts); ``M400`` answers once all
moves are done; ``M410`` aborts planned moves; ``M18`` disables the motors; ``G21`` mm,
``G90`` absolute positions, ``G92`` sets the current position. A board prints ``start`` after
a reset. Unknown commands get ``echo:Unknown command: "<cmd>"`` and ``ok``.

:class:`GcodeSender` keeps the host side's state: line numbers, the lines in flight (a window
of ``ok``-acknowledged lines), and a history to resend from.
"""
from __future__ import annotations

import collections
import dataclasses
import re
from typing import Dict, List, Optional


def checksum(text: str) -> int:
    """Marlin's line checksum: XOR of the bytes of ``text`` (everything before ``*``)."""
    c = 0
    for b in text.encode('ascii'):
        c ^= b
    return c


def frame_line(number: int, command: str) -> str:
    """``N<number> <command>*<checksum>`` (no line end)."""
    body = f"N{number} {command}"
    return f"{body}*{checksum(body)}"


@dataclasses.dataclass
class HostLine:
    """A line as the board parses it (:func:`parse_host_line`)."""

    command: str                 #: the command without line number, checksum and comment
    number: Optional[int]        #: line number, None if unnumbered
    has_checksum: bool
    checksum_ok: bool


def parse_host_line(line: str) -> HostLine:
    """Split a received host line into number, command and checksum validity (board side)."""
    text = line.strip()
    if ';' in text:
        text = text[:text.index(';')].rstrip()
    number = None
    has_cs, ok = False, True
    if '*' in text:
        body, _, cs = text.rpartition('*')
        has_cs = True
        try:
            ok = int(cs.strip()) == checksum(body)
        except ValueError:
            ok = False
        text = body
    m = re.match(r'N(-?\d+)\s*', text)
    if m:
        number = int(m.group(1))
        text = text[m.end():]
    return HostLine(command=text.strip(), number=number, has_checksum=has_cs, checksum_ok=ok)


@dataclasses.dataclass
class Reply:
    """One parsed board line; ``kind`` is one of ok, resend, position, start, echo, error, busy, other."""

    kind: str
    text: str
    line: Optional[int] = None                   #: resend: first line to send again
    axes: Optional[Dict[str, float]] = None      #: position: planned position per axis (axis units)
    counts: Optional[Dict[str, int]] = None      #: position: step count per axis


_AXIS_RX = re.compile(r'([XYZE]):\s*(-?\d+(?:\.\d*)?)')


def parse_reply(line: str) -> Reply:
    """Classify a line from the board (host side); never raises on garbage (kind 'other')."""
    text = line.strip()
    low = text.lower()
    if low == 'ok' or low.startswith('ok '):
        return Reply('ok', text)
    if low.startswith('resend:') or low.startswith('rs '):
        m = re.search(r'(\d+)', text)
        return Reply('resend', text, line=int(m.group(1))) if m else Reply('other', text)
    if low == 'start':
        return Reply('start', text)
    if low.startswith('error:') or low.startswith('!!'):
        return Reply('error', text)
    if low.startswith('echo:busy') or low.startswith('busy:'):
        return Reply('busy', text)
    if low.startswith('echo:') or low.startswith('//'):
        return Reply('echo', text)
    if 'Count' in text:
        head, _, tail = text.partition('Count')
        axes = {k: float(v) for k, v in _AXIS_RX.findall(head)}
        counts = {k: int(float(v)) for k, v in _AXIS_RX.findall(tail)}
        if axes and counts:
            return Reply('position', text, axes=axes, counts=counts)
    return Reply('other', text)


def format_position(axes: Dict[str, float], counts: Dict[str, int], e: float = 0.0) -> str:
    """An M114 report: ``X:1.00 Y:2.00 Z:0.00 E:0.00 Count X:80 Y:160 Z:0`` (board side)."""
    head = ' '.join(f"{k}:{axes[k]:.2f}" for k in ('X', 'Y', 'Z') if k in axes)
    tail = ' '.join(f"{k}:{counts[k]}" for k in ('X', 'Y', 'Z') if k in counts)
    return f"{head} E:{e:.2f} Count {tail}"


def format_axes(command: str, values: Dict[str, float], decimals: int = 4) -> str:
    """``G1 X1.2500 Y0.0000`` style command from axis values (in the given order)."""
    return ' '.join([command] + [f"{k}{v:.{decimals}f}" for k, v in values.items()])


class GcodeSender:
    """Host side of Marlin's line protocol: numbering, an ``ok`` window, resends.

    Parameters
    ----------
    window : int
        Lines in flight without an ``ok`` (1: one command per ``ok``).
    history : int
        Sent lines kept for ``Resend:`` requests.
    """

    def __init__(self, window: int = 1, history: int = 256):
        if window < 1:
            raise ValueError(f"window {window} must be >= 1")
        self.window = window
        self.history_size = history
        self.resends = 0
        self.reset()

    def reset(self) -> None:
        """Forget everything; the next line is ``M110 N0`` numbered 0 (call on (re)connect)."""
        self.pending: collections.deque = collections.deque()   # commands not yet numbered
        self.retry: collections.deque = collections.deque()     # numbers to send again
        self.sent: collections.OrderedDict = collections.OrderedDict()  # number -> command
        self.in_flight: collections.deque = collections.deque()  # numbers awaiting ok
        self.next_number = 0
        self.pending.append('M110 N0')

    @property
    def queue_depth(self) -> int:
        """Commands waiting to be written (not counting those in flight)."""
        return len(self.pending) + len(self.retry)

    def enqueue(self, command: str) -> None:
        self.pending.append(command)

    def sendable(self) -> List[str]:
        """Framed lines to write now (the window allowing); they count as in flight."""
        out = []
        while len(self.in_flight) < self.window and (self.retry or self.pending):
            if self.retry:
                n = self.retry.popleft()
                cmd = self.sent[n]
            else:
                cmd = self.pending.popleft()
                if cmd.startswith('M110'):
                    n = int(re.search(r'N(\d+)', cmd).group(1)) if re.search(r'N(\d+)', cmd) else 0
                    self.next_number = n
                n = self.next_number
                self.next_number += 1
                self.sent[n] = cmd
                while len(self.sent) > self.history_size:
                    self.sent.popitem(last=False)
            self.in_flight.append(n)
            out.append(frame_line(n, cmd))
        return out

    def send_unnumbered(self, command: str) -> str:
        """``command`` for writing at once, past the window and the queue, without a line
        number (``M410``: Marlin acts on it when it arrives); its ``ok`` is counted as usual."""
        self.in_flight.append(-1)     # never refused, never resent
        return command

    def abort(self) -> int:
        """Drop everything not yet taken by the board (queued and to-be-resent lines) and
        re-synchronise the numbering with ``M110``; return how many commands were dropped."""
        n = len(self.pending) + len(self.retry)
        self.pending.clear()
        self.retry.clear()
        self.pending.append(f"M110 N{self.next_number}")
        return n

    def in_flight_commands(self) -> List[str]:
        return [self.sent.get(n, 'unnumbered') for n in self.in_flight]

    def on_ok(self) -> Optional[str]:
        """An ``ok``: the oldest line in flight is acknowledged; return its command (or None)."""
        if not self.in_flight:
            return None   # an extra ok (Marlin 1 sends one after Resend)
        n = self.in_flight.popleft()
        return self.sent.get(n, 'unnumbered')

    def on_resend(self, number: int) -> bool:
        """``Resend: number``: send lines from ``number`` again; False if it is no longer known.

        Nothing sent since :meth:`reset`: the request is about a line of the numbering before
        it (one written just before the board reset, answered after); the queued ``M110 N0``
        sets the numbering anew, so there is nothing to resend and nothing to drop.
        """
        if not self.sent:
            return True
        if number not in self.sent:
            if number == self.next_number:
                # the board expects the line after all we numbered: it is in sync (a garbled
                # M110 whose only job was that), and what is in flight was not taken
                self.resends += 1
                self.in_flight.clear()
                return True
            return False
        self.resends += 1
        again = [n for n in self.sent if n >= number]
        # lines before `number` were taken (their oks may still come); the rest is resent
        self.in_flight = collections.deque(n for n in self.in_flight if n < number)
        self.retry = collections.deque(again + [n for n in self.retry if n not in again])
        return True
