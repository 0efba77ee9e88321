"""Frozen-camera detection on rendered frames: repeats are caught, live noisy frames never are."""
import numpy as np
import pytest

from frog_vision.core.frame_check import FrozenFrameDetector
from frog_vision.core.renderer import RenderSettings, TankRenderer


def test_a_repeated_frame_is_frozen_from_the_nth_copy_and_a_change_ends_it(camera, camera_pose):
    frame = TankRenderer(camera, camera_pose, RenderSettings(noise_sigma=2.0)).render(np.array([0.0, 0.0, 0.3]))
    d = FrozenFrameDetector(3)
    # the same bytes in new buffers (a driver republishing its last image)
    got = [(d.check(bytes(frame.tobytes())), d.repeated) for _ in range(6)]
    # every copy is a repeat (never posed); frozen (warned about) from the third
    assert got == [(False, False), (False, True)] + [(True, True)] * 4
    assert d.run == 6 and d.frozen_total == 4
    changed = frame.copy()
    changed[240, 320, 1] ^= 1                       # one bit of one pixel
    assert d.check(changed) is False and d.run == 1 and not d.frozen and not d.repeated
    assert d.check(changed) is False and d.check(changed) is True


def test_live_frames_of_a_still_robot_are_never_frozen(camera, camera_pose):
    """The twin's camera (noise, corner jitter) renders a still robot differently every frame; without
    noise and jitter the frames are byte-identical, as a frozen driver's are."""
    noisy = TankRenderer(camera, camera_pose, RenderSettings(noise_sigma=2.0, seed=3))
    d = FrozenFrameDetector(2)
    pose = np.array([0.05, -0.02, 1.0])
    assert not any(d.check(noisy.render(pose)) for _ in range(20))
    ideal = TankRenderer(camera, camera_pose, RenderSettings(noise_sigma=0.0, corner_jitter_px=0.0))
    d = FrozenFrameDetector(2)
    assert [d.check(ideal.render(pose)) for _ in range(3)] == [False, True, True]


def test_lengths_count_and_bad_settings():
    d = FrozenFrameDetector(2)
    assert d.check(b"\x00" * 10) is False
    assert d.check(b"\x00" * 11) is False           # another length: another frame
    d.reset()
    assert d.check(b"\x00" * 11) is False and d.run == 1
    for bad in (1, 0, 2.5):
        with pytest.raises(ValueError, match="frozen_frames"):
            FrozenFrameDetector(bad)
