"""Model of the relay and the robot behind the serial port (for tests and the digital twin).

The firmware side parses ``p``/``h`` lines like the robot (:func:`protocol.decode_command`).
The BLE hop from the nRF52 dev-kit to the robot's BL652 is modelled as a delay per line:
a BLE write is sent at the next connection event, so the delay is a fixed processing time
plus a uniform wait over one connection interval, with lines kept in order (the link layer
is ordered), and an optional loss rate (a line that never arrives).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .protocol import Blank, DecodeError, Heat, SetPulse, decode_command

# Defaults: UART + relay + robot processing ~3 ms; a 15 ms connection interval (a common
# nRF52 central setting between the 7.5 ms minimum and 30 ms). The hardware logs show the
# heading reacting 0.15-0.2 s after a decision, which includes SMA heating and the stroke:
# the BLE hop is a small part of it.
DEFAULT_BLE_LATENCY_S = 0.003
DEFAULT_BLE_INTERVAL_S = 0.015


@dataclass
class BleLinkModel:
    """Delay and loss of the relay -> robot BLE hop.

    Parameters
    ----------
    latency_s : float
        Fixed part of the delay [s].
    interval_s : float
        Connection interval [s]; the delay adds a uniform wait in [0, interval_s).
    loss_rate : float
        Probability that a line is lost, 0-1.
    rng : numpy.random.Generator
        Source of the jitter and losses.
    """

    latency_s: float = DEFAULT_BLE_LATENCY_S
    interval_s: float = DEFAULT_BLE_INTERVAL_S
    loss_rate: float = 0.0
    rng: np.random.Generator | None = None

    def __post_init__(self):
        if not (self.latency_s >= 0 and self.interval_s >= 0 and 0 <= self.loss_rate <= 1):
            raise ValueError(f"BLE model needs latency_s >= 0 ({self.latency_s}), interval_s >= 0 "
                             f"({self.interval_s}), loss_rate in [0, 1] ({self.loss_rate})")
        self.rng = self.rng if self.rng is not None else np.random.default_rng()
        self._last_delivery = -math.inf

    def delivery_time(self, received_at: float) -> float | None:
        """When a line the relay received at ``received_at`` reaches the robot; None = lost."""
        if self.loss_rate > 0 and self.rng.random() < self.loss_rate:
            return None
        t = received_at + self.latency_s + self.interval_s * self.rng.random()
        t = max(t, self._last_delivery)          # ordered delivery
        self._last_delivery = t
        return t


@dataclass(frozen=True)
class Fire:
    """The robot heats ``limbs`` for ``pulse_s``."""

    limbs: tuple[int, ...]
    pulse_s: float


class RobotFirmware:
    """The robot's command interpreter: ``p`` sets the pulse, ``h`` fires limbs."""

    def __init__(self, pulse_ms: int = 80):
        self.pulse_ms = pulse_ms
        self.errors = 0

    def handle(self, line: bytes) -> Fire | SetPulse | Blank | DecodeError:
        cmd = decode_command(line)
        if isinstance(cmd, DecodeError):
            self.errors += 1
            return cmd
        if isinstance(cmd, SetPulse):
            self.pulse_ms = cmd.ms
            return cmd
        if isinstance(cmd, Heat):
            return Fire(cmd.limbs, self.pulse_ms / 1000.0)
        return cmd
