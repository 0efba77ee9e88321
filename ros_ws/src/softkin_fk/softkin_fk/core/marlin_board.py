"""An emulated Marlin board: the protocol of :mod:`.marlin` and a timed motion model (no I/O).

What it does, as far as the finger's driver uses Marlin:

* lines with ``N``: the number must follow the last one (``M110`` sets it) and the checksum
  must match, else ``Error:<reason>, Last Line: <n>`` and ``Resend: <n + 1>`` (Marlin 2: no
  ``ok`` with it); accepted commands are answered ``ok``;
* ``G0/G1`` (absolute or relative, ``F`` modal, axis units as set by ``steps_per_unit``),
  ``G21``, ``G90``, ``G91``, ``G92``, ``M110``, ``M114``, ``M400``, ``M410``, ``M18``/``M84``,
  ``M17``, ``M115`` (firmware report), ``M211`` (soft endstops: off, like a board without
  endstops whose zero the host declares); anything else: ``echo:Unknown command: "<cmd>"`` and ``ok``;
* motion: a planner of ``buffer_size`` moves executed one after another, each a straight
  line in step space at its feedrate (no acceleration ramps: a move of length d at F takes
  exactly ``60 d / F`` s); the ``ok`` of a move waits while the planner is full and the ``ok``
  of ``M400`` until all moves are done, and commands after a waiting one wait too;
* ``M114`` reports the planned position and the steppers' real-time counts;
* faults: :meth:`MarlinBoard.reset` (banner ``start``; counts and line number back to 0, the
  motors physically stay where they are), :meth:`MarlinBoard.corrupt_next` (the next numbered
  line is taken as a checksum mismatch, like line noise), :meth:`MarlinBoard.inject_error`.

The *physical* motor positions (microsteps from the cable's rest) are kept apart from the
board's counts, which a reset or ``G92`` re-zeroes: :meth:`MarlinBoard.physical_steps`.
"""
from __future__ import annotations

import collections
import dataclasses
import re
from typing import Dict, List, Optional

import numpy as np

from .marlin import format_position, parse_host_line

BANNER = ["start", "echo:Marlin 2.1.2 (softkin_fk emulator)", "echo: Last Updated: emulated | Author: softkin_fk",
          "echo:Free Memory: 4096  PlannerBufferBytes: 1024"]

FIRMWARE_REPORT = ("FIRMWARE_NAME:Marlin 2.1.2 (softkin_fk emulator) SOURCE_CODE_URL:github.com/MarlinFirmware/Marlin "
                   "PROTOCOL_VERSION:1.0 MACHINE_TYPE:softkin finger EXTRUDER_COUNT:0")


@dataclasses.dataclass
class _Move:
    start: np.ndarray       # counts at the start
    end: np.ndarray         # counts at the end
    duration: float         # s
    queued: float           # time it entered the planner
    t0: Optional[float] = None


class MarlinBoard:
    """Emulated Marlin (see module docstring).

    Parameters
    ----------
    axes : sequence of str
        Axis letters the board drives (X, Y, Z by default).
    steps_per_unit : float
        Microsteps per axis unit (M92), the same for every axis.
    buffer_size : int
        Planner moves held at once (Marlin's BLOCK_BUFFER_SIZE: 16).
    """

    def __init__(self, axes=('X', 'Y', 'Z'), steps_per_unit: float = 80.0, buffer_size: int = 16):
        self.axes = list(axes)
        self.spu = float(steps_per_unit)
        self.buffer_size = int(buffer_size)
        self._phys_at_reset = np.zeros(len(self.axes), np.int64)
        self.moves_done = 0            #: completed moves (for the move-end topic)
        self.received: List[str] = []  #: every accepted command, in order
        self.errors = 0
        self.enabled = False
        self._out: List[str] = []
        self._completed: List[np.ndarray] = []
        self._power_on(initial=True)

    # --- state ---------------------------------------------------------------------------
    def _power_on(self, initial: bool = False) -> None:
        phys = np.zeros(len(self.axes), np.int64) if initial else self.physical_steps()
        self._offset = phys.copy()            # physical = counts + offset
        self.counts = np.zeros(len(self.axes), np.int64)
        self.planned = np.zeros(len(self.axes))   # planned position (axis units)
        self.last_n = 0
        self.absolute = True
        self.feedrate = 1500.0                # units/min (Marlin's default-ish)
        self.moves: collections.deque = collections.deque()
        self.inbox: collections.deque = collections.deque()
        self._waiting = None                  # (kind, command) blocking the command queue
        self._corrupt = 0
        self._out.extend(BANNER)

    def physical_steps(self) -> np.ndarray:
        """Motor positions in microsteps from the cables' rest (not re-zeroed by resets)."""
        return self.counts + self._offset

    def busy(self) -> bool:
        return bool(self.moves)

    # --- faults --------------------------------------------------------------------------
    def reset(self) -> None:
        """A board reset: planner and line number cleared, banner printed; motors stay put."""
        self._power_on()

    def corrupt_next(self, n: int = 1) -> None:
        """Take the next ``n`` numbered lines as checksum mismatches."""
        self._corrupt += n

    def inject_error(self, text: str = "Printer halted. kill() called!") -> None:
        self._out.append(f"Error:{text}")

    # --- I/O -----------------------------------------------------------------------------
    def receive(self, line: str, now: float) -> None:
        """A line from the host (processed now or, behind a waiting command, later).

        ``M410`` acts at once, ahead of waiting commands (Marlin's emergency parser).
        """
        if 'M410' in line:
            self._advance(now)
            self.moves.clear()
            self.planned = self.counts / self.spu
        self.inbox.append(line)
        self.tick(now)

    def take_output(self) -> List[str]:
        """Lines for the host since the last call."""
        out, self._out = self._out, []
        return out

    def velocity(self) -> np.ndarray:
        """Motor speeds (microsteps/s) of the move in progress; zeros at rest."""
        if not self.moves or self.moves[0].t0 is None or self.moves[0].duration <= 0:
            return np.zeros(len(self.axes))
        m = self.moves[0]
        return (m.end - m.start) / m.duration

    def take_completed(self) -> List[tuple]:
        """``(end time, physical step positions)`` of each move finished since the last call."""
        out, self._completed = self._completed, []
        return out

    # --- motion --------------------------------------------------------------------------
    def tick(self, now: float) -> None:
        """Advance motion to ``now`` and process whatever commands can proceed."""
        self._advance(now)
        while True:
            if self._waiting is not None:
                kind, _ = self._waiting
                if kind == 'planner' and len(self.moves) < self.buffer_size:
                    self._waiting = None
                    self._out.append('ok')
                elif kind in ('m400', 'm18') and not self.moves:
                    self._waiting = None
                    if kind == 'm18':
                        self.enabled = False
                    self._out.append('ok')
                else:
                    return
            if not self.inbox:
                return
            self._process(self.inbox.popleft(), now)

    def _advance(self, now: float) -> None:
        while self.moves:
            m = self.moves[0]
            if m.t0 is None:
                m.t0 = m.queued
            u = (now - m.t0) / m.duration if m.duration > 0 else 1.0
            if u >= 1.0:
                self.counts = m.end.copy()
                self.moves.popleft()
                self.moves_done += 1
                self._completed.append((m.t0 + m.duration, self.physical_steps()))
                if self.moves:   # back to back, no gap (or from when it was queued)
                    nxt = self.moves[0]
                    nxt.t0 = max(m.t0 + m.duration, nxt.queued)
                continue
            self.counts = np.rint(m.start + (m.end - m.start) * u).astype(np.int64)
            return

    def position_report(self) -> str:
        axes = dict(zip(self.axes, self.planned))
        counts = dict(zip(self.axes, self.counts.tolist()))
        return format_position(axes, counts)

    def _line_error(self, reason: str) -> None:
        self.errors += 1
        self._out.append(f"Error:{reason}, Last Line: {self.last_n}")
        self._out.append(f"Resend: {self.last_n + 1}")

    def _process(self, raw: str, now: float) -> None:
        if not raw.strip():
            return
        hl = parse_host_line(raw)
        if hl.number is not None:
            is_m110 = hl.command.startswith('M110')
            if self._corrupt > 0:
                self._corrupt -= 1
                self._line_error("checksum mismatch")
                self.inbox.clear()    # Marlin flushes its receive buffer
                return
            if hl.number != self.last_n + 1 and not is_m110:
                self._line_error("Line Number is not Last Line Number+1")
                self.inbox.clear()
                return
            if not hl.has_checksum:
                self._line_error("No Checksum with line number")
                self.inbox.clear()
                return
            if not hl.checksum_ok:
                self._line_error("checksum mismatch")
                self.inbox.clear()
                return
            self.last_n = hl.number
        self._execute(hl.command, now)

    def _words(self, cmd: str) -> Dict[str, float]:
        out = {}
        for k, v in re.findall(r'([A-Z])\s*(-?\d+(?:\.\d*)?|-?\.\d+)', cmd[cmd.find(' '):] if ' ' in cmd else ''):
            out[k] = float(v)
        return out

    def _execute(self, cmd: str, now: float) -> None:
        self.received.append(cmd)
        code = cmd.split()[0].upper() if cmd.split() else ''
        w = self._words(cmd)
        if code in ('G0', 'G1'):
            target = self.planned.copy()
            for i, ax in enumerate(self.axes):
                if ax in w:
                    target[i] = w[ax] if self.absolute else target[i] + w[ax]
            if 'F' in w and w['F'] > 0:
                self.feedrate = w['F']
            start = self.moves[-1].end if self.moves else self.counts
            end = np.rint(target * self.spu).astype(np.int64)
            self.planned = target
            self.enabled = True
            dist = float(np.linalg.norm((end - start) / self.spu))
            if dist > 0:
                self.moves.append(_Move(start.copy(), end, 60.0 * dist / self.feedrate, now))
            if len(self.moves) >= self.buffer_size:
                self._waiting = ('planner', cmd)   # ok once a slot frees
                return
        elif code == 'G92':
            for i, ax in enumerate(self.axes):
                if ax in w:
                    phys = self.physical_steps()[i]
                    self.planned[i] = w[ax]
                    self.counts[i] = int(round(w[ax] * self.spu))
                    self._offset[i] = phys - self.counts[i]
        elif code in ('G21', 'M110', 'M17'):
            if code == 'M17':
                self.enabled = True
            if code == 'M110' and 'N' in w:
                self.last_n = int(w['N'])
        elif code == 'G90':
            self.absolute = True
        elif code == 'G91':
            self.absolute = False
        elif code == 'M114':
            self._out.append(self.position_report())
        elif code == 'M115':
            self._out.append(FIRMWARE_REPORT)
        elif code == 'M211':
            zeros = ' '.join(f'{ax}0.00' for ax in self.axes)
            self._out.append(f'echo:Soft endstops: Off   Min:  {zeros}   Max:  {zeros}')
        elif code == 'M400':
            if self.moves:
                self._waiting = ('m400', cmd)
                return
        elif code == 'M410':
            pass   # quickstop already done on receipt (see receive)
        elif code in ('M18', 'M84'):
            if self.moves:    # Marlin finishes the planned moves, then disables
                self._waiting = ('m18', cmd)
                return
            self.enabled = False
        else:
            self._out.append(f'echo:Unknown command: "{cmd}"')
        self._out.append('ok')
