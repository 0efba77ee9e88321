"""The robot's planar pose in the tank from its tag, with a covariance from the geometry.

The tag lies in the horizontal plane ``z = tag_height`` of the tank. Its four corners'
viewing rays (undistorted with the camera model) meet that plane in four points; a 2-D
rigid fit (Kabsch) to the tag's known corners gives the tag's (x, y, yaw), and the fixed
tag-to-body offset gives the body frame's pose (REP-103: x forward, heading
counter-clockwise from tank x). The covariance is the corner noise propagated through the
fit (numerical Jacobian of pose w.r.t. the 8 corner coordinates).
"""
from __future__ import annotations

import dataclasses

import numpy as np

from frog_vision.core.camera_model import CameraModel
from frog_vision.core.detection import TAG_CORNERS_UNIT, Detection
from frog_vision.core.robot_shape import COM_AHEAD_OF_RING_CENTRE
from frog_vision.core.tank_calibration import CameraPose
from frog_common.se2 import wrap_angle
from frog_common.settings import Settings, setting


def tag_size_setting():
    """The tag's edge: one definition for the pose estimator and the renderer."""
    return setting(0.047, "edge of the tag's detected square", min=0.005, max=1.0, unit="m")


def tag_height_setting():
    """The tag face's height over the board: one definition for the pose estimator and the renderer."""
    return setting(0.0, "height of the tag face above the board plane z = 0", min=-0.5, max=0.5, unit="m")


@dataclasses.dataclass(frozen=True)
class PoseSettings(Settings):
    """Settings of :class:`TagPoseEstimator`.

    Attributes
    ----------
    tag_size : float
        Edge of the detected square [m] (the authors' tag: 47 mm).
    tag_height : float
        Height of the tag face above the tank plane z = 0 of the board [m].
    offset_x, offset_y, offset_yaw : float
        Pose of the body frame in the tag frame [m, m, rad] (tag frame: x = printed tag's
        right, y = its top). Default: the tag on the body's centre, aligned with it; the
        body frame's origin at the centre of mass, 3.4 mm ahead (``robot_shape``).
    corner_sigma_px : float
        Corner noise used for the covariance [px]; the fit's own residual is used when larger.
    border_margin_px : float
        Reject tags with a corner closer than this to the image border (half out of view).
    max_size_error : float
        Reject tags whose fitted edge differs from ``tag_size`` by more than this fraction
        (a wrong quad, a tag partly hidden or tilted out of the plane).
    """

    tag_size: float = tag_size_setting()
    tag_height: float = tag_height_setting()
    offset_x: float = setting(COM_AHEAD_OF_RING_CENTRE, "body frame origin (centre of mass) in the tag frame, x",
                              min=-0.5, max=0.5, unit="m")
    offset_y: float = setting(0.0, "body frame origin in the tag frame, y", min=-0.5, max=0.5, unit="m")
    offset_yaw: float = setting(0.0, "body frame yaw in the tag frame", min=-3.1416, max=3.1416, unit="rad")
    corner_sigma_px: float = setting(0.2, "corner noise for the pose covariance", min=0.01, max=10.0, unit="px")
    border_margin_px: float = setting(3.0, "reject tags with a corner closer than this to the image border",
                                      min=0.0, max=1000.0, unit="px")
    max_size_error: float = setting(0.08, "reject tags whose fitted edge differs from tag_size by more than this "
                                    "fraction", min=0.0, max=10.0)


@dataclasses.dataclass(frozen=True)
class PoseMeasurement:
    """Body pose in the tank frame from one detection.

    Attributes
    ----------
    pose : ndarray, shape (3,)
        x [m], y [m], heading [rad] in (-pi, pi].
    covariance : ndarray, shape (3, 3)
    tag_pose : ndarray, shape (3,)
        The tag frame's pose.
    residual_px : float
        RMS distance between the detected corners and the fitted tag's reprojection [px].
    size_ratio : float
        Fitted tag edge / ``tag_size``.
    """

    pose: np.ndarray
    covariance: np.ndarray
    tag_pose: np.ndarray
    residual_px: float
    size_ratio: float


class TagPoseEstimator:
    """Turn tag detections into body poses (see the module docstring)."""

    def __init__(self, camera: CameraModel, camera_pose: CameraPose, settings: PoseSettings | None = None):
        self.camera = camera
        self.camera_pose = camera_pose
        self.settings = settings or PoseSettings()
        self._model = TAG_CORNERS_UNIT * self.settings.tag_size / 2

    def check(self, det: Detection) -> str | None:
        """Why a detection cannot be used, or ``None``."""
        m = self.settings.border_margin_px
        c = det.corners
        if (c.min() < m or c[:, 0].max() > self.camera.width - 1 - m
                or c[:, 1].max() > self.camera.height - 1 - m):
            return "tag touches the image border"
        return None

    def _fit(self, plane_pts: np.ndarray):
        """Rigid 2-D fits of the model corners to (..., 4, 2) plane points -> (x, y, yaw), scale."""
        mean = plane_pts.mean(axis=-2)
        d = plane_pts - mean[..., None, :]
        m = self._model          # centred already
        # Kabsch in 2-D: angle of sum over corners of m_k x d_k and m_k . d_k
        sxx = np.sum(m[:, 0] * d[..., 0] + m[:, 1] * d[..., 1], axis=-1)
        sxy = np.sum(m[:, 0] * d[..., 1] - m[:, 1] * d[..., 0], axis=-1)
        yaw = np.arctan2(sxy, sxx)
        scale = np.hypot(sxx, sxy) / np.sum(m ** 2)
        return np.concatenate([mean, yaw[..., None]], axis=-1), scale

    def measure(self, det: Detection) -> tuple[PoseMeasurement | None, str | None]:
        """(measurement, None), or (None, reason) when the detection is rejected."""
        reason = self.check(det)
        if reason:
            return None, reason
        s = self.settings
        corners = np.asarray(det.corners, float)
        # 8 perturbed corner sets for the Jacobian (central differences) + the nominal one
        h = 0.05
        eye = np.eye(8).reshape(8, 4, 2) * h
        sets = np.concatenate([corners[None], corners + eye, corners - eye])
        xy = self.camera.normalized(sets.reshape(-1, 2))
        plane = self.camera_pose.normalized_to_plane(xy, s.tag_height).reshape(-1, 4, 2)
        poses, scales = self._fit(plane)
        tag_pose, scale = poses[0], float(scales[0])
        if abs(scale - 1.0) > s.max_size_error:
            return None, f"tag edge is {scale * 100:.0f} % of the expected {s.tag_size * 1e3:.0f} mm"
        dp = poses[1:9] - poses[9:]
        dp[:, 2] = wrap_angle(dp[:, 2])
        jac = (dp / (2 * h)).T                                    # (3, 8)
        # residual of the rigid fit, mapped back to pixels
        c, sn = np.cos(tag_pose[2]), np.sin(tag_pose[2])
        fitted = self._model @ np.array([[c, sn], [-sn, c]]) + tag_pose[:2]
        pts = np.column_stack([fitted, np.full(4, s.tag_height)])
        resid = float(np.sqrt(np.mean(np.sum((self.camera_pose.project(self.camera, pts) - corners) ** 2,
                                             axis=1))))
        sigma = max(s.corner_sigma_px, resid)
        cov_tag = sigma ** 2 * jac @ jac.T
        body, jb = compose_offset(tag_pose, (s.offset_x, s.offset_y, s.offset_yaw))
        cov = jb @ cov_tag @ jb.T
        return PoseMeasurement(body, cov, tag_pose, resid, scale), None


def compose_offset(pose, offset) -> tuple[np.ndarray, np.ndarray]:
    """Pose ``pose`` (x, y, yaw) composed with a relative pose ``offset`` -> (pose, Jacobian)."""
    x, y, a = pose
    ox, oy, oa = offset
    c, s = np.cos(a), np.sin(a)
    out = np.array([x + c * ox - s * oy, y + s * ox + c * oy, wrap_angle(a + oa)])
    jac = np.array([[1, 0, -s * ox - c * oy], [0, 1, c * ox - s * oy], [0, 0, 1.0]])
    return out, jac


def invert_pose(pose) -> np.ndarray:
    """The inverse of a planar pose (x, y, yaw)."""
    x, y, a = pose
    c, s = np.cos(a), np.sin(a)
    return np.array([-c * x - s * y, s * x - c * y, -a])
