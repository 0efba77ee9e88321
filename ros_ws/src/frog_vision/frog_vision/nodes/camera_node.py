"""``camera_node``: a real camera as ``camera/image_raw`` (bgr8) + ``camera/camera_info``.

``source`` picks the camera: a V4L2/USB device (``/dev/video0`` or an index ``0``) or a
video file through OpenCV, or ``realsense`` for an Intel RealSense colour stream through
pyrealsense2 (optional; a clear message when it is not installed). Frames are stamped with
the node clock when they are read. A source that cannot be opened stops the node with exit
code 2 naming it, or, with ``retry``, is retried every ``retry_period_s`` with a logged error.
"""
from __future__ import annotations

import os
import sys

from rclpy.node import Node
from rclpy.qos import QoSProfile
from sensor_msgs.msg import CameraInfo, Image
from soft_robot_common.diagnostics import ERROR, OK, WARN, NodeDiagnostics
from soft_robot_common import ConfigurationError, Param, declare_parameters, run_node

from frog_vision.core.camera_model import CameraModel
from frog_vision.nodes.common import load_camera
from frog_vision.nodes.messages import array_to_image, camera_info_msg

PARAMS = [
    Param("source", "/dev/video0", "camera: a device path or index (0 or '0'), a video file, or 'realsense'",
          ints_as_text=True),
    Param("width", 640, "requested frame width [px]", min=16, max=8192),
    Param("height", 480, "requested frame height [px]", min=16, max=8192),
    Param("fps", 30.0, "requested frame rate [Hz]", min=1.0, max=240.0),
    Param("camera_info_file", "", "camera_calibration YAML; empty = the RealSense 640x480 default scaled "
          "to the frame size (uncalibrated)"),
    Param("frame_id", "camera", "frame of the images"),
    Param("loop", False, "restart a video file at its end"),
    Param("retry", False, "keep retrying a source that cannot be opened or stops delivering"),
    Param("retry_period_s", 2.0, "with retry: seconds between attempts to open a camera that failed or was "
          "lost [s]", min=0.1, max=60.0),
]


class _OpenCvSource:
    def __init__(self, source: str, width: int, height: int, fps: float):
        import cv2
        self.cv2 = cv2
        self.is_file = os.path.isfile(source)
        target = int(source) if source.isdigit() else source
        if not self.is_file and isinstance(target, str) and not os.path.exists(target):
            raise OSError(f"camera source {source!r}: no such device or file")
        self.cap = cv2.VideoCapture(target)
        if not self.cap.isOpened():
            raise OSError(f"camera source {source!r} cannot be opened by OpenCV")
        if not self.is_file:
            self.cap.set(cv2.CAP_PROP_FRAME_WIDTH, width)
            self.cap.set(cv2.CAP_PROP_FRAME_HEIGHT, height)
            self.cap.set(cv2.CAP_PROP_FPS, fps)
        ok, frame = self.cap.read()
        if not ok or frame is None:
            raise OSError(f"camera source {source!r} opened but delivers no frames (unreadable file?)")
        self.first = frame

    def read(self):
        if self.first is not None:
            f, self.first = self.first, None
            return f
        ok, frame = self.cap.read()
        return frame if ok else None

    def rewind(self) -> None:
        self.cap.set(self.cv2.CAP_PROP_POS_FRAMES, 0)

    def close(self) -> None:
        self.cap.release()


class _RealSenseSource:
    is_file = False

    def __init__(self, width: int, height: int, fps: float):
        try:
            import pyrealsense2 as rs
        except ImportError as exc:
            raise OSError("source 'realsense' needs pyrealsense2, which is not installed "
                          "(pip install pyrealsense2)") from exc
        import numpy as np
        self.np = np
        self.pipe = rs.pipeline()
        cfg = rs.config()
        cfg.enable_stream(rs.stream.color, width, height, rs.format.bgr8, int(fps))
        try:
            self.pipe.start(cfg)
        except RuntimeError as exc:
            raise OSError(f"RealSense: {exc}") from exc

    def read(self):
        frames = self.pipe.wait_for_frames(1000)
        color = frames.get_color_frame()
        return self.np.asanyarray(color.get_data()).copy() if color else None

    def rewind(self) -> None:
        pass

    def close(self) -> None:
        self.pipe.stop()


class CameraNode(Node):
    NODE_NAME = "camera_node"

    def __init__(self):
        super().__init__("camera_node")
        p = declare_parameters(self, PARAMS)
        self.cfg = p
        self.model = load_camera(p["camera_info_file"])
        self.source = None
        self.source_error = ""
        self.warned_uncalibrated = False
        self._open(first=True)
        self.image_pub = self.create_publisher(Image, "camera/image_raw", QoSProfile(depth=2))
        self.info_pub = self.create_publisher(CameraInfo, "camera/camera_info", QoSProfile(depth=2))
        self.create_timer(1.0 / p["fps"], self.tick)
        self.retry_timer = self.create_timer(p["retry_period_s"], self._retry)
        self.frames = 0
        self._diag_frames = 0
        self.diagnostics = NodeDiagnostics(self, "camera", self._diagnostics, hardware_id=str(p["source"]))

    def _diagnostics(self):
        new, self._diag_frames = self.frames - self._diag_frames, self.frames
        values = {"source": self.cfg["source"], "frames": self.frames, "frames_last_period": new,
                  "ready": self.source is not None and self.frames > 0}
        if self.source is None:
            what = f"retrying every {self.cfg['retry_period_s']:g} s" if self.cfg["retry"] else "not retrying"
            return ERROR, f"camera source not open ({self.source_error or 'ended'}); {what}", values
        if new == 0:
            return WARN, "waiting for frames from the camera source", values
        return OK, "publishing frames", values

    def _open(self, first=False) -> None:
        p = self.cfg
        try:
            if p["source"] == "realsense":
                self.source = _RealSenseSource(p["width"], p["height"], p["fps"])
            else:
                self.source = _OpenCvSource(p["source"], p["width"], p["height"], p["fps"])
            self.get_logger().info(f"camera source {p['source']!r} open")
        except OSError as exc:
            self.source = None
            self.source_error = str(exc)
            if first and not p["retry"]:
                raise ConfigurationError(str(exc)) from exc
            self.get_logger().error(f"{exc}; retrying every {p['retry_period_s']:g} s")

    def _retry(self) -> None:
        if self.source is None:
            self._open()

    def tick(self) -> None:
        if self.source is None:
            return
        frame = self.source.read()
        if frame is None:
            if self.source.is_file and self.cfg["loop"]:
                self.source.rewind()
                return
            if self.source.is_file:
                self.get_logger().info(f"end of the video file {self.cfg['source']!r}")
            else:
                self.get_logger().error(f"camera source {self.cfg['source']!r} stopped delivering frames"
                                        + ("; reopening" if self.cfg["retry"] else ""))
            self.source.close()
            self.source = None
            if not self.cfg["retry"]:
                self.retry_timer.cancel()
            return
        if frame.ndim != 3 or frame.shape[2] != 3:
            self.get_logger().error(f"camera delivered a frame of shape {frame.shape}; expected BGR")
            return
        h, w = frame.shape[:2]
        if self.model is None or (self.model.width, self.model.height) != (w, h):
            if self.model is not None and self.cfg["camera_info_file"]:
                self.get_logger().error(f"frame is {w}x{h} but camera_info_file is for "
                                        f"{self.model.width}x{self.model.height}: publishing it scaled")
            self.model = (self.model or CameraModel.realsense_640x480()).scaled(w, h)
            if not self.cfg["camera_info_file"] and not self.warned_uncalibrated:
                self.get_logger().warn("no camera_info_file: publishing default (uncalibrated) intrinsics")
                self.warned_uncalibrated = True
        stamp = self.get_clock().now().to_msg()
        self.image_pub.publish(array_to_image(frame, stamp, self.cfg["frame_id"]))
        self.frames += 1
        self.info_pub.publish(camera_info_msg(self.model, stamp, self.cfg["frame_id"]))


def main(args=None) -> int:
    return run_node(CameraNode, args)


if __name__ == "__main__":
    sys.exit(main())
