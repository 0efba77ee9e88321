"""The emulated relay and robot: firmware parsing, BLE delay model."""


import numpy as np
import pytest

from frog_bridge.core.emulator import BleLinkModel, Fire, RobotFirmware
from frog_bridge.core.protocol import DecodeError, SetPulse


def test_firmware_sets_pulse_and_fires():
    fw = RobotFirmware(pulse_ms=80)
    assert fw.handle(b"h 1 0\n") == Fire((1, 0), 0.08)
    assert fw.handle(b"p 120\n") == SetPulse(120)
    assert fw.handle(b"h  2 3\r\n") == Fire((2, 3), 0.12)
    assert isinstance(fw.handle(b"h 9\n"), DecodeError) and fw.errors == 1


def test_ble_delay_is_bounded_ordered_and_lossy():
    m = BleLinkModel(latency_s=0.003, interval_s=0.015, rng=np.random.default_rng(0))
    t_rx = np.cumsum(np.random.default_rng(1).exponential(0.005, 2000))
    t = np.array([m.delivery_time(x) for x in t_rx])
    d = t - t_rx
    assert d.min() >= 0.003 and np.all(np.diff(t) >= 0)
    # without reordering the delay is uniform on [3, 18) ms: mean ~10.5 ms
    free = BleLinkModel(0.003, 0.015, rng=np.random.default_rng(2))
    dd = np.array([free.delivery_time(10.0 * k) - 10.0 * k for k in range(4000)])
    assert dd.max() < 0.018 and abs(dd.mean() - 0.0105) < 5e-4
    lossy = BleLinkModel(0.0, 0.0, loss_rate=0.3, rng=np.random.default_rng(3))
    lost = sum(lossy.delivery_time(float(k)) is None for k in range(5000))
    assert abs(lost / 5000 - 0.3) < 0.03
    with pytest.raises(ValueError):
        BleLinkModel(loss_rate=1.5)


