"""Where the camera is over the tank: its pose from a board of tags at known positions.

Frames: ``tank`` (REP-103: x, y in the tank plane, z up; the board lies in z = 0) and the
camera's optical frame (z along the viewing direction, x right and y down in the image).
A :class:`CameraPose` holds the rotation from camera to tank and the camera centre in the
tank frame; :func:`calibrate_tank` finds it from detections of board tags by PnP
(OpenCV ``solvePnP``, SQPnP start then Levenberg-Marquardt refinement).
"""
from __future__ import annotations

import dataclasses
import datetime
from importlib import resources
from pathlib import Path

import cv2
import numpy as np
import yaml

from frog_vision.core.camera_model import CameraModel
from frog_vision.core.detection import TAG_CORNERS_UNIT
from frog_vision.core.tag_images import FAMILIES


def default_board_file() -> Path:
    """The board shipped with the package (``frog_vision/data/tank_board.yaml``)."""
    return Path(str(resources.files("frog_vision") / "data" / "tank_board.yaml"))


@dataclasses.dataclass(frozen=True)
class BoardTag:
    """A board tag: id, detected-square edge ``size`` [m], centre (x, y) [m] and yaw [rad]."""

    tag_id: int
    size: float
    x: float
    y: float
    yaw: float = 0.0

    def corners(self) -> np.ndarray:
        """Tank coordinates (z = 0) of the detected corners, order of ``TAG_CORNERS_UNIT``."""
        c, s = np.cos(self.yaw), np.sin(self.yaw)
        local = TAG_CORNERS_UNIT * self.size / 2
        xy = local @ np.array([[c, s], [-s, c]]) + [self.x, self.y]
        return np.column_stack([xy, np.zeros(4)])


@dataclasses.dataclass(frozen=True)
class Board:
    """Tags at known positions in the tank plane."""

    family: str
    tags: tuple

    def __post_init__(self):
        if self.family not in FAMILIES:
            raise ValueError(f"board family {self.family!r} is not one of {', '.join(FAMILIES)}")
        ids = [t.tag_id for t in self.tags]
        if len(set(ids)) != len(ids):
            raise ValueError(f"board tag ids {ids} are not unique")
        if len(ids) < 1:
            raise ValueError("the board has no tags")
        for t in self.tags:
            if not (np.isfinite([t.size, t.x, t.y, t.yaw]).all() and t.size > 0):
                raise ValueError(f"board tag {t.tag_id}: size must be > 0 and the pose finite")

    def tag(self, tag_id: int) -> BoardTag | None:
        return next((t for t in self.tags if t.tag_id == tag_id), None)

    @classmethod
    def from_yaml(cls, path=None) -> "Board":
        """Load a board file (``family`` and a list of ``{id, size, x, y, yaw}``); ``None``
        loads the default board."""
        path = Path(path) if path is not None else default_board_file()
        if not path.is_file():
            raise FileNotFoundError(f"board file {path} does not exist")
        try:
            data = yaml.safe_load(path.read_text())
            tags = tuple(BoardTag(int(t["id"]), float(t["size"]), float(t["x"]), float(t["y"]),
                                  float(t.get("yaw", 0.0))) for t in data["tags"])
            return cls(str(data["family"]), tags)
        except (yaml.YAMLError, KeyError, TypeError) as exc:
            raise ValueError(f"{path}: expected 'family' and 'tags' with id, size, x, y "
                             f"(and optional yaw) per tag ({exc!r})") from exc

    def to_yaml(self, path) -> None:
        data = {"family": self.family,
                "tags": [{"id": t.tag_id, "size": t.size, "x": t.x, "y": t.y, "yaw": t.yaw}
                         for t in self.tags]}
        Path(path).write_text(yaml.safe_dump(data, sort_keys=False))


@dataclasses.dataclass
class CameraPose:
    """Camera pose over the tank.

    Attributes
    ----------
    rotation : ndarray, shape (3, 3)
        Camera optical frame -> tank frame (columns: camera axes in tank coordinates).
    position : ndarray, shape (3,)
        Camera centre in the tank frame [m].
    """

    rotation: np.ndarray
    position: np.ndarray

    def __post_init__(self):
        self.rotation = np.asarray(self.rotation, float).reshape(3, 3)
        self.position = np.asarray(self.position, float).reshape(3)

    @classmethod
    def overhead(cls, height: float = 0.8, x: float = 0.0, y: float = 0.0, tilt_x: float = 0.0,
                 tilt_y: float = 0.0, yaw: float = 0.0) -> "CameraPose":
        """A camera ``height`` [m] above (x, y), looking down, image right = tank +y and
        image down = tank +x (the tank's long side along the image's); optional small
        tilts [rad] about tank x and y and a yaw about z (applied in that order)."""
        # camera x = tank +y, camera y = tank +x, camera z = tank -z
        base = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
        rot = _rot_z(yaw) @ _rot_y(tilt_y) @ _rot_x(tilt_x) @ base
        return cls(rot, np.array([x, y, height]))

    @property
    def tilt(self) -> float:
        """Angle between the optical axis and straight down [rad]."""
        return float(np.arccos(np.clip(-self.rotation[2, 2], -1.0, 1.0)))

    def tank_to_camera(self, points) -> np.ndarray:
        """Tank points (N, 3) -> camera optical frame (N, 3)."""
        return (np.asarray(points, float).reshape(-1, 3) - self.position) @ self.rotation

    def project(self, camera: CameraModel, points) -> np.ndarray:
        """Pixels (N, 2) of tank points (N, 3), with the camera's distortion."""
        rvec, tvec = self.opencv_extrinsics()
        uv, _ = cv2.projectPoints(np.asarray(points, float).reshape(-1, 3), rvec, tvec,
                                  camera.K, camera.D)
        return uv.reshape(-1, 2)

    def opencv_extrinsics(self) -> tuple[np.ndarray, np.ndarray]:
        """(rvec, tvec) mapping tank to camera coordinates, as OpenCV wants them."""
        r_ct = self.rotation.T
        return cv2.Rodrigues(r_ct)[0].ravel(), -r_ct @ self.position

    def pixels_to_plane(self, camera: CameraModel, pixels, z: float = 0.0) -> np.ndarray:
        """Where the viewing rays of pixels (N, 2) meet the plane ``z`` of the tank -> (N, 2)."""
        return self.normalized_to_plane(camera.normalized(pixels), z)

    def normalized_to_plane(self, xy, z: float = 0.0) -> np.ndarray:
        """Like :meth:`pixels_to_plane` from undistorted normalised coordinates (N, 2)."""
        xy = np.asarray(xy, float).reshape(-1, 2)
        rays = np.column_stack([xy, np.ones(len(xy))]) @ self.rotation.T
        lam = (z - self.position[2]) / rays[:, 2]
        return self.position[:2] + lam[:, None] * rays[:, :2]

    def to_dict(self) -> dict:
        w, x, y, zq = _quaternion(self.rotation)
        return {"position": [float(v) for v in self.position],
                "rotation": [[float(v) for v in row] for row in self.rotation],
                "quaternion_xyzw": [x, y, zq, w],
                "tilt_deg": float(np.degrees(self.tilt))}

    @classmethod
    def from_dict(cls, d: dict) -> "CameraPose":
        rot = np.asarray(d["rotation"], float)
        if rot.shape != (3, 3) or not np.allclose(rot.T @ rot, np.eye(3), atol=1e-6):
            raise ValueError(f"rotation {rot.tolist()} is not a 3x3 rotation matrix")
        return cls(rot, d["position"])


@dataclasses.dataclass
class TankCalibration:
    """Result of :func:`calibrate_tank`, saved as YAML."""

    pose: CameraPose
    reprojection_rms_px: float
    reprojection_max_px: float
    n_points: int
    tag_ids: tuple
    image_size: tuple
    board: str = ""

    def to_yaml(self, path) -> None:
        data = {"camera_pose": self.pose.to_dict(),
                "reprojection_rms_px": float(self.reprojection_rms_px),
                "reprojection_max_px": float(self.reprojection_max_px),
                "n_points": int(self.n_points), "tag_ids": [int(i) for i in self.tag_ids],
                "image_size": [int(v) for v in self.image_size], "board": self.board,
                "created": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
                "frames": "camera_pose maps the camera optical frame (z forward, x right, y down) "
                          "to tank (REP-103); position = camera centre [m]"}
        Path(path).write_text(yaml.safe_dump(data, sort_keys=False, default_flow_style=None))

    @classmethod
    def from_yaml(cls, path) -> "TankCalibration":
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"tank calibration file {path} does not exist")
        try:
            d = yaml.safe_load(path.read_text())
            return cls(CameraPose.from_dict(d["camera_pose"]), float(d["reprojection_rms_px"]),
                       float(d.get("reprojection_max_px", d["reprojection_rms_px"])),
                       int(d.get("n_points", 0)), tuple(d.get("tag_ids", ())),
                       tuple(d.get("image_size", ())), str(d.get("board", "")))
        except (yaml.YAMLError, KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"{path}: not a tank calibration file ({exc})") from exc


def calibrate_tank(camera: CameraModel, detections_per_image, board: Board,
                   board_name: str = "") -> TankCalibration:
    """Camera pose over the tank from board-tag detections in one or more images of a
    fixed camera.

    Parameters
    ----------
    camera : CameraModel
    detections_per_image : iterable of list of Detection
    board : Board

    Returns
    -------
    TankCalibration

    Raises
    ------
    ValueError
        Fewer than two board tags seen (one tag is a weak, nearly planar-ambiguous fit).
    """
    obj, img, seen = [], [], set()
    for dets in detections_per_image:
        for d in dets:
            t = board.tag(d.tag_id)
            if t is None:
                continue
            obj.append(t.corners())
            img.append(np.asarray(d.corners, float))
            seen.add(d.tag_id)
    if len(seen) < 2:
        raise ValueError(f"need at least 2 board tags in view, saw {sorted(seen)} of "
                         f"{[t.tag_id for t in board.tags]} ({board.family})")
    obj = np.concatenate(obj)
    img = np.concatenate(img)
    ok, rvec, tvec = cv2.solvePnP(obj, img, camera.K, camera.D, flags=cv2.SOLVEPNP_SQPNP)
    if not ok:
        raise ValueError("PnP failed on the board detections")
    rvec, tvec = cv2.solvePnPRefineLM(obj, img, camera.K, camera.D, rvec, tvec)
    r_ct = cv2.Rodrigues(rvec)[0]
    pose = CameraPose(r_ct.T, -r_ct.T @ tvec.ravel())
    err = np.linalg.norm(pose.project(camera, obj) - img, axis=1)
    return TankCalibration(pose, float(np.sqrt(np.mean(err ** 2))), float(err.max()), len(obj),
                           tuple(sorted(seen)), (camera.width, camera.height), board_name)


def _rot_x(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _rot_y(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _rot_z(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def _quaternion(r) -> tuple[float, float, float, float]:
    """(w, x, y, z) of a rotation matrix (Shepperd's method)."""
    tr = np.trace(r)
    if tr > 0:
        s = 2 * np.sqrt(1 + tr)
        w, x, y, z = s / 4, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s
    else:
        i = int(np.argmax(np.diag(r)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2 * np.sqrt(1 + r[i, i] - r[j, j] - r[k, k])
        q = np.zeros(3)
        q[i] = s / 4
        q[j] = (r[j, i] + r[i, j]) / s
        q[k] = (r[k, i] + r[i, k]) / s
        w = (r[k, j] - r[j, k]) / s
        x, y, z = q
    return float(w), float(x), float(y), float(z)
