"""Pinhole camera with lens distortion, in the ROS ``camera_info`` conventions.

Intrinsics ``K`` (3x3), distortion ``D`` (``plumb_bob``: k1 k2 p1 p2 k3;
``rational_polynomial``: 8 coefficients), rectification ``R`` and projection ``P``, loaded
from and saved to the YAML file that ``camera_calibration`` writes
(``image_width``, ``camera_matrix: {rows, cols, data}``, ...). Projection and undistortion
use OpenCV's model, which is the one ROS uses. Pixel coordinates follow OpenCV: the centre
of the top-left pixel is (0, 0).
"""
from __future__ import annotations

import dataclasses
from pathlib import Path

import cv2
import numpy as np
import yaml

DISTORTION_MODELS = {"plumb_bob": (5,), "rational_polynomial": (8,)}

#: The authors' camera: Intel RealSense D435 colour stream at 640x480 (typical factory
#: intrinsics of that stream; replace with your camera's calibration file).
REALSENSE_640x480 = dict(width=640, height=480, fx=615.0, fy=615.0, cx=320.0, cy=240.0)


@dataclasses.dataclass
class CameraModel:
    """Intrinsic camera model.

    Attributes
    ----------
    width, height : int
        Image size [px].
    K : ndarray, shape (3, 3)
        Camera matrix [[fx, 0, cx], [0, fy, cy], [0, 0, 1]].
    D : ndarray, shape (5,) or (8,)
        Distortion coefficients of ``distortion_model``.
    distortion_model : str
        ``plumb_bob`` or ``rational_polynomial``.
    R : ndarray, shape (3, 3)
        Rectification (identity for a monocular camera).
    P : ndarray, shape (3, 4)
        Projection of the rectified image (``[K | 0]`` when not given).
    camera_name : str
    """

    width: int
    height: int
    K: np.ndarray
    D: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(5))
    distortion_model: str = "plumb_bob"
    R: np.ndarray = dataclasses.field(default_factory=lambda: np.eye(3))
    P: np.ndarray | None = None
    camera_name: str = "camera"

    def __post_init__(self):
        self.width, self.height = int(self.width), int(self.height)
        self.K = np.asarray(self.K, float).reshape(3, 3)
        self.D = np.asarray(self.D, float).ravel()
        self.R = np.asarray(self.R, float).reshape(3, 3)
        self.P = (np.hstack([self.K, np.zeros((3, 1))]) if self.P is None
                  else np.asarray(self.P, float).reshape(3, 4))
        if self.width <= 0 or self.height <= 0:
            raise ValueError(f"image size {self.width}x{self.height} must be positive")
        if self.distortion_model not in DISTORTION_MODELS:
            raise ValueError(f"distortion model {self.distortion_model!r} is not supported "
                             f"(expected one of {', '.join(DISTORTION_MODELS)})")
        if self.D.size == 0:
            self.D = np.zeros(DISTORTION_MODELS[self.distortion_model][0])
        if self.D.size not in DISTORTION_MODELS[self.distortion_model]:
            raise ValueError(f"{self.distortion_model} needs {DISTORTION_MODELS[self.distortion_model][0]} "
                             f"distortion coefficients, got {self.D.size}")
        fx, fy = self.K[0, 0], self.K[1, 1]
        if not (np.all(np.isfinite(self.K)) and fx > 0 and fy > 0 and np.all(np.isfinite(self.D))):
            raise ValueError(f"camera matrix must be finite with fx, fy > 0, got K = {self.K.tolist()}")

    # -- construction ----------------------------------------------------------------------
    @classmethod
    def pinhole(cls, width: int = 640, height: int = 480, fx: float = 615.0, fy: float | None = None,
                cx: float | None = None, cy: float | None = None, D=None,
                camera_name: str = "camera") -> "CameraModel":
        """A camera from focal length [px] and principal point (defaults: image centre)."""
        fy = fx if fy is None else fy
        cx = (width - 1) / 2.0 if cx is None else cx
        cy = (height - 1) / 2.0 if cy is None else cy
        K = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1.0]])
        return cls(width, height, K, np.zeros(5) if D is None else np.asarray(D, float),
                   camera_name=camera_name)

    @classmethod
    def realsense_640x480(cls) -> "CameraModel":
        """Default model of the authors' camera (no distortion: the D435 colour stream is
        delivered rectified with near-zero coefficients)."""
        return cls.pinhole(camera_name="realsense_color", **REALSENSE_640x480)

    @classmethod
    def from_camera_info(cls, info: dict) -> "CameraModel":
        """From a dict of ``sensor_msgs/CameraInfo`` fields (``width``, ``height``, ``k``,
        ``d``, ``distortion_model``, ``r``, ``p``)."""
        return cls(info["width"], info["height"], info["k"], info.get("d", ()),
                   info.get("distortion_model") or "plumb_bob",
                   info.get("r", np.eye(3)) if np.any(info.get("r", [1])) else np.eye(3),
                   info.get("p") if np.any(info.get("p", [0])) else None)

    def to_camera_info(self) -> dict:
        """Fields of a ``sensor_msgs/CameraInfo`` (flat lists, as the message holds them)."""
        return dict(width=self.width, height=self.height, distortion_model=self.distortion_model,
                    d=self.D.tolist(), k=self.K.ravel().tolist(), r=self.R.ravel().tolist(),
                    p=self.P.ravel().tolist())

    @classmethod
    def from_yaml(cls, path) -> "CameraModel":
        """Load a ``camera_calibration`` YAML file.

        Raises
        ------
        FileNotFoundError, ValueError
            Missing file, or a field missing or malformed (the message names it).
        """
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"camera calibration file {path} does not exist")
        try:
            data = yaml.safe_load(path.read_text())
        except yaml.YAMLError as exc:
            raise ValueError(f"{path}: not valid YAML ({exc})") from exc
        if not isinstance(data, dict):
            raise ValueError(f"{path}: expected a camera_info mapping")

        def matrix(key, shape, required=True):
            if key not in data:
                if required:
                    raise ValueError(f"{path}: field {key!r} is missing")
                return None
            m = data[key]
            try:
                values = np.asarray(m["data"], float)
                rows, cols = int(m["rows"]), int(m["cols"])
            except (KeyError, TypeError, ValueError) as exc:
                raise ValueError(f"{path}: field {key!r} needs rows, cols and data") from exc
            if values.size != rows * cols or (shape and (rows, cols) != shape):
                raise ValueError(f"{path}: field {key!r} is {rows}x{cols} with {values.size} values")
            return values.reshape(rows, cols)

        for key in ("image_width", "image_height"):
            if key not in data:
                raise ValueError(f"{path}: field {key!r} is missing")
        D = matrix("distortion_coefficients", None, required=False)
        R = matrix("rectification_matrix", (3, 3), required=False)
        return cls(data["image_width"], data["image_height"], matrix("camera_matrix", (3, 3)),
                   np.zeros(0) if D is None else D.ravel(),
                   data.get("distortion_model", "plumb_bob"),
                   np.eye(3) if R is None else R, matrix("projection_matrix", (3, 4), required=False),
                   str(data.get("camera_name", "camera")))

    def to_yaml(self, path) -> None:
        """Write the ``camera_calibration`` YAML format."""
        def m(a):
            a = np.atleast_2d(a)
            return {"rows": int(a.shape[0]), "cols": int(a.shape[1]),
                    "data": [float(v) for v in a.ravel()]}
        data = {"image_width": self.width, "image_height": self.height,
                "camera_name": self.camera_name, "camera_matrix": m(self.K),
                "distortion_model": self.distortion_model,
                "distortion_coefficients": m(self.D.reshape(1, -1)),
                "rectification_matrix": m(self.R), "projection_matrix": m(self.P)}
        Path(path).write_text(yaml.safe_dump(data, sort_keys=False, default_flow_style=None))

    # -- geometry ------------------------------------------------------------------------
    @property
    def has_distortion(self) -> bool:
        return bool(np.any(self.D != 0))

    def project(self, points_camera) -> np.ndarray:
        """Pixels of points given in the camera's optical frame (z forward) [m] -> (N, 2)."""
        pts = np.asarray(points_camera, float).reshape(-1, 3)
        uv, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), self.K, self.D)
        return uv.reshape(-1, 2)

    def normalized(self, pixels) -> np.ndarray:
        """Undistorted normalised image coordinates (x/z, y/z) of pixels -> (N, 2)."""
        uv = np.asarray(pixels, float).reshape(-1, 1, 2)
        if not self.has_distortion:
            d = uv.reshape(-1, 2) - self.K[:2, 2]
            y = d[:, 1] / self.K[1, 1]
            return np.column_stack([(d[:, 0] - self.K[0, 1] * y) / self.K[0, 0], y])
        crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-10)
        return cv2.undistortPoints(uv, self.K, self.D, None, None, criteria=crit).reshape(-1, 2)

    def rays(self, pixels) -> np.ndarray:
        """Unit viewing rays (camera optical frame) through pixels -> (N, 3)."""
        xy = self.normalized(pixels)
        r = np.hstack([xy, np.ones((len(xy), 1))])
        return r / np.linalg.norm(r, axis=1, keepdims=True)

    def undistort_pixels(self, pixels) -> np.ndarray:
        """Where pixels would be in an ideal (distortion-free) image with the same ``K``."""
        xy = self.normalized(pixels)
        return xy @ self.K[:2, :2].T + self.K[:2, 2]

    def undistort_image(self, image: np.ndarray) -> np.ndarray:
        """The image as a distortion-free camera with the same ``K`` would see it."""
        self.check_image(image)
        if not self.has_distortion:
            return image
        return cv2.undistort(image, self.K, self.D)

    def check_image(self, image: np.ndarray) -> None:
        """Raise ``ValueError`` when an image does not have this camera's size."""
        h, w = image.shape[:2]
        if (w, h) != (self.width, self.height):
            raise ValueError(f"image is {w}x{h} but the camera model is {self.width}x{self.height}")

    def scaled(self, width: int, height: int) -> "CameraModel":
        """The same camera at another resolution (binning / resizing)."""
        sx, sy = width / self.width, height / self.height
        K = self.K.copy()
        K[0] *= sx
        K[1] *= sy
        K[0, 2] = (self.K[0, 2] + 0.5) * sx - 0.5
        K[1, 2] = (self.K[1, 2] + 0.5) * sy - 0.5
        return CameraModel(width, height, K, self.D.copy(), self.distortion_model,
                           camera_name=self.camera_name)
