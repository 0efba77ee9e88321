"""AprilTag detection with pupil-apriltags: one family, chosen ids, everything else ignored.

Corner order (libapriltag): ``corners[k]`` is the detected square's corner at tag-frame
coordinates ``TAG_CORNERS_UNIT[k] * size / 2``, with the tag frame's x along the printed
tag's right, y along its top and z out of the printed face (``test_detection`` checks this
on rendered tags).
"""
from __future__ import annotations

import dataclasses

import numpy as np

from frog_common.settings import Settings, setting
from frog_vision.core.tag_images import FAMILIES

#: Tag-frame corner directions of ``Detection.corners`` (bottom-left, bottom-right,
#: top-right, top-left of the printed tag).
TAG_CORNERS_UNIT = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])


@dataclasses.dataclass(frozen=True)
class Detection:
    """One detected tag.

    Attributes
    ----------
    tag_id : int
    corners : ndarray, shape (4, 2)
        Pixel coordinates (distorted image), order of ``TAG_CORNERS_UNIT``.
    center : ndarray, shape (2,)
    decision_margin : float
        libapriltag's decoding margin (higher = more confident).
    hamming : int
        Corrected bit errors.
    """

    tag_id: int
    corners: np.ndarray
    center: np.ndarray
    decision_margin: float
    hamming: int


@dataclasses.dataclass(frozen=True)
class DetectorSettings(Settings):
    """Settings of :class:`TagDetector` (pupil-apriltags names in parentheses).

    Attributes
    ----------
    family : str
        Tag family (``families``); the robot carries ``tagStandard41h12``.
    tag_ids : tuple of int
        Ids to report; empty = all ids of the family.
    decimate : float
        Quad detection on an image decimated by this factor (``quad_decimate``); corners
        are still refined on the full image when ``refine_edges``.
    threads : int
        Worker threads (``nthreads``).
    refine_edges : bool
        Snap the quad edges to the strongest full-resolution gradients (``refine_edges``).
    sigma : float
        Gaussian blur before quad detection [px] (``quad_sigma``).
    sharpening : float
        (``decode_sharpening``).
    max_hamming : int
        Reject detections with more corrected bits than this.
    """

    family: str = setting("tagStandard41h12", "tag family", choices=FAMILIES)
    tag_ids: tuple = setting((47,), "ids to report; empty = all ids of the family")
    decimate: float = setting(2.0, "quad detection decimation (pupil-apriltags quad_decimate)", min=1.0, max=8.0)
    threads: int = setting(1, "detector threads", min=1, max=16)
    refine_edges: bool = setting(True, "refine the quad edges on the full image")
    sigma: float = setting(0.0, "Gaussian blur before quad detection", min=0.0, max=10.0, unit="px")
    sharpening: float = setting(0.25, "decode sharpening", min=0.0, max=10.0)
    max_hamming: int = setting(1, "reject detections with more corrected bits than this", min=0, max=3)

    def __post_init__(self):
        object.__setattr__(self, "tag_ids", tuple(int(i) for i in self.tag_ids))
        super().__post_init__()


class TagDetector:
    """Detect the tags of one family in grey or BGR images.

    Examples
    --------
    >>> det = TagDetector(DetectorSettings(family="tag36h11", tag_ids=()))
    >>> det.detect(np.full((480, 640), 128, np.uint8))
    []
    """

    def __init__(self, settings: DetectorSettings | None = None):
        self.settings = settings or DetectorSettings()
        self._detector = _native_detector(self.settings)

    def detect(self, image: np.ndarray, roi: tuple | None = None) -> list[Detection]:
        """Detections of the wanted ids, best decision margin first.

        Parameters
        ----------
        image : ndarray
            Grey (H, W) or BGR (H, W, 3), uint8.
        roi : (x0, y0, x1, y1), optional
            Search only this window (pixel bounds, clipped to the image); the corners are
            still reported in full-image coordinates.

        Raises
        ------
        ValueError
            The image is not a 2-D grey or 3-channel BGR uint8 array.
        """
        grey = to_grey(image)
        ox = oy = 0
        if roi is not None:
            h, w = grey.shape
            x0, y0 = max(int(roi[0]), 0), max(int(roi[1]), 0)
            x1, y1 = min(int(roi[2]), w), min(int(roi[3]), h)
            if x1 - x0 < 16 or y1 - y0 < 16:
                return []
            grey = np.ascontiguousarray(grey[y0:y1, x0:x1])
            ox, oy = x0, y0
        found = self._detector.detect(grey)
        off = np.array([ox - 0.5, oy - 0.5])
        ids = self.settings.tag_ids
        out = [Detection(int(d.tag_id), np.asarray(d.corners, float) + off, np.asarray(d.center, float) + off,
                         float(d.decision_margin), int(d.hamming))
               for d in found
               if (not ids or d.tag_id in ids) and d.hamming <= self.settings.max_hamming]
        out.sort(key=lambda d: -d.decision_margin)
        return out


_DETECTORS: dict = {}


def _native_detector(s: DetectorSettings):
    """One pupil-apriltags detector per configuration, kept for the process's life:
    pupil-apriltags 1.0.4's ``Detector.__del__`` can crash the interpreter (it frees the
    families before the detector), so detectors are never destroyed."""
    import pupil_apriltags

    class _KeptDetector(pupil_apriltags.Detector):
        def __del__(self):
            pass

    key = (s.family, int(s.threads), float(s.decimate), float(s.sigma), bool(s.refine_edges),
           float(s.sharpening))
    if key not in _DETECTORS:
        _DETECTORS[key] = _KeptDetector(
            families=s.family, nthreads=int(s.threads), quad_decimate=float(s.decimate),
            quad_sigma=float(s.sigma), refine_edges=int(bool(s.refine_edges)),
            decode_sharpening=float(s.sharpening))
    return _DETECTORS[key]


def to_grey(image: np.ndarray) -> np.ndarray:
    """A contiguous uint8 grey image from grey or BGR input (``ValueError`` otherwise)."""
    import cv2
    a = np.asarray(image)
    if a.dtype != np.uint8:
        raise ValueError(f"image dtype is {a.dtype}, expected uint8")
    if a.ndim == 3 and a.shape[2] == 3:
        return cv2.cvtColor(a, cv2.COLOR_BGR2GRAY)
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[:, :, 0]
    if a.ndim != 2:
        raise ValueError(f"image shape {a.shape} is neither grey (H, W) nor BGR (H, W, 3)")
    return np.ascontiguousarray(a)
