"""Tracking accuracy on rendered sequences of frog_sim's simulated frog swimming and turning,
against the renderer's exact ground truth (the table: bench/vision_accuracy.py)."""
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))

from frog_vision.core.camera_model import CameraModel  # noqa: E402
from frog_vision.core.renderer import RenderSettings, TankRenderer  # noqa: E402
from frog_vision.core.tank_calibration import CameraPose  # noqa: E402
from frog_vision.core.tracker import Tracker  # noqa: E402
from vision_sequences import RING_CENTRE_POSE, run_simulated, simulated_sequence  # noqa: E402

CAMERA = CameraModel.realsense_640x480()
POSE = CameraPose.overhead(0.8)


@pytest.fixture(scope="module")
def swim():
    return simulated_sequence(duration=8.0)


def _run(swim, occlusion=(), kicks=True, **render):
    """Track the sequence; ``kicks``: give the tracker the simulator's limb firings (as
    tracker_node gets them from frog/bridge/sent)."""
    r = TankRenderer(CAMERA, POSE, RenderSettings(**render))
    truth, shapes, firings = swim
    tracker = Tracker(CAMERA, POSE, pose=RING_CENTRE_POSE)
    return run_simulated(r, tracker, truth, shapes, firings if kicks else (), occlusion=occlusion)


def test_the_sequence_swims_and_turns(swim):
    truth, _, kicks = swim
    assert len(kicks) >= 10
    assert np.ptp(truth.pose[:, 0]) + np.ptp(truth.pose[:, 1]) > 0.05
    assert np.ptp(np.unwrap(truth.pose[:, 2])) > np.radians(15)
    assert truth.twist[:, 0].max() > 0.02


@pytest.mark.slow
def test_clean_frames_at_the_authors_geometry(swim):
    m = _run(swim, noise_sigma=2.0).metrics()
    assert m["detection_rate"] >= 0.99
    assert m["position_mean_mm"] <= 1.0 and m["heading_mean_deg"] <= 0.5


# Against the simulator's instantaneous twist, which jumps within the ~0.35 s power stroke (yaw
# rate 0 -> 20-45 deg/s in 2-3 frames, with frame-to-frame wobble), even differences of the EXACT
# poses err by 3.3 mm/s and 3.3 deg/s RMS over this sequence (5.6 / 5.9 inside the strokes):
# no causal estimate from 30 fps poses can beat raw differences by 5x in yaw rate here.
@pytest.mark.slow
def test_filter_with_kick_inputs_beats_raw_differences_at_the_authors_noise(swim):
    m = _run(swim, noise_sigma=5.0, corner_jitter_px=0.2).metrics()
    assert m["position_mean_mm"] <= 1.0
    # The target is 5x in velocity; on this simulator's sharp, fast-decaying kicks the filter
    # reaches 3.51x in velocity and 1.62x in yaw rate (render seed 0), so this bound guards the
    # measured value and the 5x target is missed (docs/results.md).
    assert m["velocity_ratio"] >= 3.3, m
    assert m["yaw_rate_ratio"] >= 1.5, m


@pytest.mark.slow
def test_filter_without_kick_inputs_the_lower_bound(swim):
    """The same without the firing times (a camera-only tracker): the constant-twist filter."""
    with_kicks = _run(swim, noise_sigma=5.0, corner_jitter_px=0.2).metrics()
    m = _run(swim, kicks=False, noise_sigma=5.0, corner_jitter_px=0.2).metrics()
    # measured (seed 0): 2.67x in velocity, 0.97x in yaw rate; a constant-twist filter cannot
    # follow the sharp strokes
    assert m["velocity_ratio"] >= 2.5, m
    assert m["yaw_rate_ratio"] >= 0.9, m
    assert with_kicks["yaw_rate_rms_deg_s"] < 0.8 * m["yaw_rate_rms_deg_s"]
    assert with_kicks["velocity_rms_mm_s"] < m["velocity_rms_mm_s"]


@pytest.mark.slow
def test_recovers_within_3_frames_after_1_s_hidden(swim):
    res = _run(swim, occlusion=[(3.0, 4.0)], noise_sigma=3.0)
    assert not res.detected[res.occluded].any()
    assert res.frames_to_recover() <= 3
