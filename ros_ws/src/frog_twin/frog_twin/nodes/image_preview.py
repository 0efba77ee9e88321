"""``image_preview``: a reduced-rate JPEG copy of a camera stream, for recordings and viewers.

Raw 640x480 colour frames at 30 fps are ~28 MB/s; a twin run records this copy instead
(sensor_msgs/CompressedImage, which Foxglove shows directly). Frames are taken at most
``rate_hz`` per second of the node's clock (simulated time in the twin) and keep their
capture stamps.
"""

from __future__ import annotations

import sys

import cv2
import numpy as np
from rclpy.node import Node
from rclpy.qos import QoSProfile, qos_profile_sensor_data
from sensor_msgs.msg import CompressedImage, Image
from soft_robot_common import Param, declare_parameters, run_node

_PARAMS = [
    Param("rate_hz", 5.0, "most frames per second passed on (node clock)", min=0.1, max=120.0, live=True),
    Param("scale", 1.0, "resize factor of the copy", min=0.1, max=1.0, live=True),
    Param("jpeg_quality", 80, "JPEG quality", min=10, max=100, live=True),
]
_ENCODINGS = {"bgr8": None, "rgb8": cv2.COLOR_RGB2BGR, "mono8": cv2.COLOR_GRAY2BGR}


class ImagePreviewNode(Node):
    NODE_NAME = "image_preview"

    def __init__(self, **kwargs):
        super().__init__("image_preview", **kwargs)
        self.cfg = declare_parameters(self, _PARAMS)
        self.pub = self.create_publisher(CompressedImage, "camera/preview/compressed", QoSProfile(depth=5))
        self.create_subscription(Image, "camera/image_raw", self.on_image, qos_profile_sensor_data)
        self.last_ns = None
        self.get_logger().info(f"JPEG copy of {self.resolve_topic_name('camera/image_raw')} at <= "
                               f"{self.cfg['rate_hz']:g} Hz on {self.resolve_topic_name('camera/preview/compressed')}")

    def on_image(self, msg: Image) -> None:
        stamp_ns = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        if self.last_ns is not None and 0 <= stamp_ns - self.last_ns < 1e9 / self.cfg["rate_hz"]:
            return
        if msg.encoding not in _ENCODINGS:
            self.get_logger().error(f"cannot preview encoding {msg.encoding!r} (bgr8, rgb8, mono8)",
                                    throttle_duration_sec=5.0)
            return
        channels = 1 if msg.encoding == "mono8" else 3
        if msg.height * msg.step != len(msg.data) or msg.step < msg.width * channels:
            self.get_logger().error(f"corrupt image: {msg.width}x{msg.height}, step {msg.step}, "
                                    f"{len(msg.data)} bytes", throttle_duration_sec=5.0)
            return
        rows = np.frombuffer(msg.data, np.uint8).reshape(msg.height, msg.step)
        img = rows[:, :msg.width * channels].reshape(msg.height, msg.width, channels)
        if _ENCODINGS[msg.encoding] is not None:
            img = cv2.cvtColor(img, _ENCODINGS[msg.encoding])
        if self.cfg["scale"] < 1.0:
            img = cv2.resize(img, None, fx=self.cfg["scale"], fy=self.cfg["scale"], interpolation=cv2.INTER_AREA)
        ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, int(self.cfg["jpeg_quality"])])
        if not ok:
            self.get_logger().error("JPEG encoding failed", throttle_duration_sec=5.0)
            return
        out = CompressedImage(header=msg.header, format="jpeg")
        out.data = buf.tobytes()
        self.pub.publish(out)
        self.last_ns = stamp_ns


def main(args=None) -> int:
    return run_node(ImagePreviewNode, args)


if __name__ == "__main__":
    sys.exit(main())
