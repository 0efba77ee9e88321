"""``image_preview``: a reduced-rate JPEG copy of a camera stream, for recordings and viewers.

Raw 640x480 colour frames at 30 fps are ~28 MB/s; a twin run records this copy instead
(sensor_msgs/CompressedImage, which Foxglove shows directly). Frames are taken at most
``rate_hz`` per second of the node's clock (simulated time in the twin) and keep their
capture stamps.

The subscription is reliable with a queue of 2, like the tracker's (both camera nodes publish
reliably): a best-effort reader loses most 0.9 MB frames to fragment loss. For a camera
driver that publishes best effort, override it with
``-p qos_overrides./camera/image_raw.subscription.reliability:=best_effort``. Frames are
passed on a grid of ``1/rate_hz`` in stamp time, so a 30 fps source gives ``rate_hz`` on
average rather than one period plus the wait for the next frame. An empty (0x0) or corrupt
frame is refused with a logged reason.
"""

from __future__ import annotations

import sys

import cv2
import numpy as np
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.qos_overriding_options import QoSOverridingOptions
from sensor_msgs.msg import CompressedImage, Image
from soft_robot_common import MessageGate, NodeDiagnostics, Param, declare_parameters, run_node
from soft_robot_common.diagnostics import OK, WARN

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
        self.create_subscription(Image, "camera/image_raw", self.on_image,
                                 QoSProfile(depth=2, reliability=ReliabilityPolicy.RELIABLE),
                                 qos_overriding_options=QoSOverridingOptions.with_default_policies())
        self.next_ns = None       # stamp from which the next frame is passed on
        self.counts = {"received": 0, "passed": 0, "refused": 0}
        self._diag_received = 0
        self.last_refusal = ""
        self.gate = MessageGate(self)
        self.diagnostics = NodeDiagnostics(self, "preview", self._diagnostics)
        self.get_logger().info(f"JPEG copy of {self.resolve_topic_name('camera/image_raw')} at <= "
                               f"{self.cfg['rate_hz']:g} Hz on {self.resolve_topic_name('camera/preview/compressed')}")

    def _diagnostics(self):
        new, self._diag_received = self.counts["received"] - self._diag_received, self.counts["received"]
        values = dict(self.counts, rate_hz=float(self.cfg["rate_hz"]), ready=self.counts["received"] > 0)
        if new == 0:
            return WARN, f"waiting for {self.resolve_topic_name('camera/image_raw')}", values
        if self.counts["passed"] == 0 and self.last_refusal:
            return WARN, self.last_refusal, values
        return OK, "passing frames on", values

    def _refuse(self, text: str) -> None:
        self.counts["refused"] += 1
        self.last_refusal = text
        if self.gate.should_log("camera/image_raw", text):    # once a second per problem, a new one at once
            self.get_logger().error(f"refused camera/image_raw: {text}")

    def on_image(self, msg: Image) -> None:
        self.counts["received"] += 1
        problem = self.gate.problem(msg, stamped=False)     # the common rule: finite, sane sizes
        if problem:
            self._refuse(problem)
            return
        stamp_ns = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        period_ns = 1e9 / self.cfg["rate_hz"]
        if self.next_ns is not None and 0 < self.next_ns - stamp_ns <= period_ns:
            return        # (a stamp further back than that: the clock jumped back; start again)
        if msg.encoding not in _ENCODINGS:
            self._refuse(f"cannot preview encoding {msg.encoding!r} (bgr8, rgb8, mono8)")
            return
        channels = 1 if msg.encoding == "mono8" else 3
        if msg.width == 0 or msg.height == 0:
            self._refuse(f"empty image ({msg.width}x{msg.height}) refused")
            return
        if msg.height * msg.step != len(msg.data) or msg.step < msg.width * channels:
            self._refuse(f"corrupt image: {msg.width}x{msg.height}, step {msg.step}, {len(msg.data)} bytes")
            return
        rows = np.frombuffer(msg.data, np.uint8).reshape(msg.height, msg.step)
        img = rows[:, :msg.width * channels].reshape(msg.height, msg.width, channels)
        if _ENCODINGS[msg.encoding] is not None:
            img = cv2.cvtColor(img, _ENCODINGS[msg.encoding])
        if self.cfg["scale"] < 1.0:
            size = (max(1, round(msg.width * self.cfg["scale"])), max(1, round(msg.height * self.cfg["scale"])))
            img = cv2.resize(img, size, interpolation=cv2.INTER_AREA)
        ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, int(self.cfg["jpeg_quality"])])
        if not ok:
            self.get_logger().error("JPEG encoding failed", throttle_duration_sec=5.0)
            return
        out = CompressedImage(header=msg.header, format="jpeg")
        out.data = buf.tobytes()
        self.pub.publish(out)
        self.counts["passed"] += 1
        # the next frame is due one period after this one's slot on the grid; a source slower
        # than rate_hz (or a gap) restarts the grid at this frame
        due = self.next_ns + period_ns if self.next_ns is not None else stamp_ns + period_ns
        self.next_ns = due if stamp_ns < due <= stamp_ns + period_ns else stamp_ns + period_ns


def main(args=None) -> int:
    return run_node(ImagePreviewNode, args)


if __name__ == "__main__":
    sys.exit(main())
