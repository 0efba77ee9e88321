"""The tracking pipeline: image -> tag -> body pose -> filtered state.

Once the robot is tracked, the tag is searched for in a window around its predicted
position (a few times the tag's size in pixels), which keeps detection to a few
milliseconds per frame; the whole image is searched when the window fails or nothing is
tracked.
"""
from __future__ import annotations

import dataclasses
import time

import numpy as np

from frog_vision.core.camera_model import CameraModel
from frog_vision.core.detection import DetectorSettings, TagDetector
from frog_vision.core.frame_difference import FrameDifferenceEstimator
from frog_vision.core.pose import PoseMeasurement, PoseSettings, TagPoseEstimator, compose_offset, invert_pose
from frog_vision.core.state_filter import FilterSettings, PoseFilter, RobotState
from frog_vision.core.tank_calibration import CameraPose


#: State estimators of :class:`Tracker`.
ESTIMATORS = ("filter", "frame_difference")


@dataclasses.dataclass(frozen=True)
class TrackResult:
    """What one frame gave.

    Attributes
    ----------
    stamp : float
        Capture time [s].
    state : RobotState or None
        Filtered state at ``stamp`` (``None`` when nothing is tracked or the tag has been
        lost for longer than the coast timeout: publish nothing then).
    measurement : PoseMeasurement or None
        This frame's tag pose, if the tag was found and accepted.
    reason : str or None
        Why this frame gave no accepted measurement.
    n_detections : int
        Tags of the wanted family and id found.
    corners : ndarray (4, 2) or None
        Detected corners of the used tag.
    compute_s : float
        Detection + estimation time [s].
    """

    stamp: float
    state: RobotState | None
    measurement: PoseMeasurement | None
    reason: str | None
    n_detections: int
    corners: np.ndarray | None
    compute_s: float


class Tracker:
    """Track the robot's tag through a stream of images.

    Parameters
    ----------
    camera : CameraModel
    camera_pose : CameraPose
        From the tank calibration.
    detector, pose, filter : settings of the three stages
    search_window : float
        Side of the search window in tag sizes (0 = always search the whole image).
    estimator : {"filter", "frame_difference"}
        The state from the poses: the Kalman filter (:class:`PoseFilter`), or the authors' raw
        pose and frame-to-frame differences (:class:`FrameDifferenceEstimator`).
    """

    def __init__(self, camera: CameraModel, camera_pose: CameraPose,
                 detector: DetectorSettings | None = None, pose: PoseSettings | None = None,
                 filter: FilterSettings | None = None, search_window: float = 3.0,
                 estimator: str = "filter"):
        if estimator not in ESTIMATORS:
            raise ValueError(f"estimator {estimator!r}: expected one of {', '.join(ESTIMATORS)}")
        self.detector = TagDetector(detector)
        self.estimator = TagPoseEstimator(camera, camera_pose, pose)
        self.filter = PoseFilter(filter) if estimator == "filter" else FrameDifferenceEstimator(filter)
        self.search_window = search_window
        self.camera = camera
        self.camera_pose = camera_pose
        self.n_frames = 0
        self.n_measured = 0

    def set_camera(self, camera: CameraModel) -> None:
        """Use a new intrinsic model (camera_info changed)."""
        self.camera = camera
        self.estimator = TagPoseEstimator(camera, self.camera_pose, self.estimator.settings)

    def _window(self, stamp: float):
        """Search window (x0, y0, x1, y1) around the predicted tag, or None."""
        if self.search_window <= 0 or not self.filter.initialised:
            return None
        st = self.filter.state(stamp)
        if st is None:
            return None
        ps = self.estimator.settings
        tag, _ = compose_offset(st.pose, invert_pose((ps.offset_x, ps.offset_y, ps.offset_yaw)))
        half = self.search_window * ps.tag_size * 0.75
        ring = tag[:2] + half * np.array([[1, 1], [-1, 1], [-1, -1], [1, -1]])
        uv = self.camera_pose.project(self.camera, np.column_stack([ring, np.full(4, ps.tag_height)]))
        if not np.all(np.isfinite(uv)):
            return None
        x0, y0 = uv.min(axis=0)
        x1, y1 = uv.max(axis=0)
        return int(x0), int(y0), int(np.ceil(x1)) + 1, int(np.ceil(y1)) + 1

    def kick(self, stamp: float) -> None:
        """Limbs were fired at ``stamp`` [s] (the filter's kick input, see ``state_filter``)."""
        self.filter.kick(stamp)

    def process(self, image: np.ndarray, stamp: float) -> TrackResult:
        """Detect, measure and filter one frame captured at ``stamp`` [s].

        Raises
        ------
        ValueError
            The image is not uint8 grey/BGR or does not match the camera model's size.
        """
        self.camera.check_image(image)
        t0 = time.perf_counter()
        self.n_frames += 1
        window = self._window(stamp)
        dets = self.detector.detect(image, window) if window is not None else []
        if not dets and window is not None:
            dets = self.detector.detect(image)
        elif window is None:
            dets = self.detector.detect(image)
        meas, reason, used = None, None, None
        for d in dets:
            meas, reason = self.estimator.measure(d)
            if meas is not None:
                used = d
                break
        if not dets:
            reason = "tag not found"
        state = None
        if meas is not None:
            state, why = self.filter.update(stamp, meas.pose, meas.covariance)
            if why is None:
                self.n_measured += 1
            else:
                reason = why
        elif self.filter.initialised:
            state = self.filter.state(stamp, coasting=True)
            if state is None and stamp - self.filter.last_measurement > self.filter.settings.reset_timeout:
                self.filter.reset()
        return TrackResult(stamp, state, meas if reason is None else None, reason, len(dets),
                           None if used is None else used.corners, time.perf_counter() - t0)


def annotate(image: np.ndarray, result: TrackResult) -> np.ndarray:
    """A BGR copy of ``image`` with the detected tag's outline and the state as text (the debug image)."""
    import cv2
    out = image.copy() if image.ndim == 3 else cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    if result.corners is not None:
        cv2.polylines(out, [np.round(result.corners * 4).astype(np.int32)], True, (0, 0, 255), 1, cv2.LINE_AA, 2)
    st = result.state
    text = "lost" if st is None else (
        f"x {st.pose[0]:+.3f} y {st.pose[1]:+.3f} th {np.degrees(st.pose[2]):+.1f} "
        f"v {st.body_velocity[0] * 100:+.1f} cm/s w {np.degrees(st.body_velocity[2]):+.0f} deg/s")
    cv2.putText(out, text, (8, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 255), 1, cv2.LINE_AA)
    return out
