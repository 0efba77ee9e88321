"""Conversions between ROS messages and the core's arrays (no algorithms)."""
from __future__ import annotations

import array

import numpy as np
from builtin_interfaces.msg import Time
from sensor_msgs.msg import CameraInfo, Image

from frog_vision.core.camera_model import CameraModel

ENCODINGS = {"bgr8": 3, "rgb8": 3, "mono8": 1}


def stamp_to_s(stamp: Time) -> float:
    return stamp.sec + stamp.nanosec * 1e-9


def s_to_stamp(t: float) -> Time:
    ns = int(round(t * 1e9))
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def image_to_array(msg: Image) -> np.ndarray:
    """BGR or grey uint8 array of an Image; ``ValueError`` naming what is wrong."""
    if msg.encoding not in ENCODINGS:
        raise ValueError(f"image encoding {msg.encoding!r} is not supported (expected bgr8, rgb8 or mono8)")
    ch = ENCODINGS[msg.encoding]
    if msg.width == 0 or msg.height == 0 or msg.step < msg.width * ch:
        raise ValueError(f"image header is inconsistent: {msg.width}x{msg.height}, step {msg.step}")
    data = np.frombuffer(bytes(msg.data) if not isinstance(msg.data, (bytes, np.ndarray)) else msg.data, np.uint8)
    if data.size != msg.step * msg.height:
        raise ValueError(f"image data has {data.size} bytes, the header says {msg.step} x {msg.height}")
    img = data.reshape(msg.height, msg.step)[:, :msg.width * ch].reshape(msg.height, msg.width, ch)
    if msg.encoding == "rgb8":
        img = img[:, :, ::-1]
    return np.ascontiguousarray(img if ch == 3 else img[:, :, 0])


def array_to_image(img: np.ndarray, stamp: Time, frame_id: str) -> Image:
    msg = Image()
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    msg.height, msg.width = int(img.shape[0]), int(img.shape[1])
    msg.encoding = "bgr8" if img.ndim == 3 else "mono8"
    msg.step = msg.width * (3 if img.ndim == 3 else 1)
    # an array('B') is taken as is; bytes would be range-checked element by element when
    # ROS_PYTHON_CHECK_FIELDS=1 (70 ms for a 640x480 frame)
    msg.data = array.array("B", np.ascontiguousarray(img).tobytes())
    return msg


def camera_info_msg(model: CameraModel, stamp: Time, frame_id: str) -> CameraInfo:
    info = model.to_camera_info()
    msg = CameraInfo()
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    msg.width, msg.height = info["width"], info["height"]
    msg.distortion_model = info["distortion_model"]
    msg.d = [float(v) for v in info["d"]]
    msg.k = [float(v) for v in info["k"]]
    msg.r = [float(v) for v in info["r"]]
    msg.p = [float(v) for v in info["p"]]
    return msg


def model_from_camera_info(msg: CameraInfo) -> CameraModel:
    return CameraModel.from_camera_info(dict(width=msg.width, height=msg.height, k=list(msg.k), d=list(msg.d),
                                             distortion_model=msg.distortion_model, r=list(msg.r), p=list(msg.p)))


def planar_covariance(c3) -> list:
    """6x6 row-major covariance (x, y, z, roll, pitch, yaw) from a planar 3x3 one; the
    unobserved z, roll and pitch get a large variance."""
    c = np.zeros((6, 6))
    idx = [0, 1, 5]
    c[np.ix_(idx, idx)] = c3
    for i in (2, 3, 4):
        c[i, i] = 1e6
    return [float(v) for v in c.ravel()]
