"""AprilTag images from the libapriltag that ships inside pupil-apriltags (through ctypes).

The renderer needs the real tag textures so that the detector sees what a printed tag
looks like. pupil-apriltags wraps neither the families nor ``apriltag_to_image``; its shared
library exports one ``<family>_create`` / ``<family>_destroy`` pair per family. The image is
drawn here from the family's codes and bit positions with the layout of libapriltag's
``apriltag_to_image``: its own output is wrong for the classic families in the shipped build
(the tag36h11 images it returns do not decode), which ``test_tag_images`` checks by detection.
"""
from __future__ import annotations

import ctypes
import functools
from pathlib import Path

import numpy as np

#: Families of libapriltag 3 (the names pupil-apriltags accepts).
FAMILIES = ("tag36h11", "tag25h9", "tag16h5", "tagCircle21h7", "tagCircle49h12",
            "tagStandard41h12", "tagStandard52h13", "tagCustom48h12")


class _Family(ctypes.Structure):
    # leading fields of apriltag_family_t (apriltag.h, libapriltag 3.x); bit_x/bit_y are
    # uint32_t there but hold negative offsets for the reversed-border families
    _fields_ = [("ncodes", ctypes.c_uint32), ("codes", ctypes.POINTER(ctypes.c_uint64)),
                ("width_at_border", ctypes.c_int), ("total_width", ctypes.c_int),
                ("reversed_border", ctypes.c_bool), ("nbits", ctypes.c_uint32),
                ("bit_x", ctypes.POINTER(ctypes.c_int32)), ("bit_y", ctypes.POINTER(ctypes.c_int32))]


@functools.lru_cache(maxsize=1)
def _library() -> ctypes.CDLL:
    import pupil_apriltags
    root = Path(pupil_apriltags.__file__).parent
    for sub in ("lib", "lib64"):
        for name in ("libapriltag.so", "libapriltag.dylib", "apriltag.dll"):
            if (root / sub / name).exists():
                return ctypes.CDLL(str(root / sub / name))
    raise RuntimeError(f"libapriltag not found inside pupil-apriltags ({root})")


@functools.lru_cache(maxsize=64)
def _tag_image_cached(family: str, tag_id: int) -> tuple[np.ndarray, int]:
    if family not in FAMILIES:
        raise ValueError(f"tag family {family!r} is not one of {', '.join(FAMILIES)}")
    lib = _library()
    create = getattr(lib, f"{family}_create")
    destroy = getattr(lib, f"{family}_destroy")
    create.restype = ctypes.POINTER(_Family)
    destroy.argtypes = [ctypes.POINTER(_Family)]
    fam = create()
    try:
        if not 0 <= tag_id < fam.contents.ncodes:
            raise ValueError(f"tag id {tag_id} is out of range 0-{fam.contents.ncodes - 1} "
                             f"for family {family}")
        f = fam.contents
        border, total, n = int(f.width_at_border), int(f.total_width), int(f.nbits)
        code = int(f.codes[tag_id])
        pixels = np.zeros((total, total), np.uint8)
        # 1-cell white ring: outside the black border (classic) or inside it (reversed)
        white = border + (0 if f.reversed_border else 2)
        a, b = (total - white) // 2, (total - white) // 2 + white - 1
        pixels[a, a:b + 1] = pixels[b, a:b + 1] = pixels[a:b + 1, a] = pixels[a:b + 1, b] = 255
        start = (total - border) // 2
        for i in range(n):
            if code >> (n - 1 - i) & 1:
                pixels[start + int(f.bit_y[i]), start + int(f.bit_x[i])] = 255
    finally:
        destroy(fam)
    pixels.setflags(write=False)
    return pixels, border


def tag_image(family: str, tag_id: int) -> np.ndarray:
    """One cell per pixel image of a tag (uint8, 0 black / 255 white), as printed.

    Returns
    -------
    ndarray, shape (total_width, total_width)
        Row 0 is the top of the printed tag.
    """
    return _tag_image_cached(family, int(tag_id))[0]


def tag_border_cells(family: str) -> int:
    """Width in cells of the detected square (``width_at_border``): the edge that the
    tag size refers to (pupil-apriltags' ``tag_size`` convention)."""
    return _tag_image_cached(family, 0)[1]


def tag_total_size(family: str, tag_size: float) -> float:
    """Printed edge [m] of a tag whose detected square has edge ``tag_size`` [m]."""
    return tag_size * tag_image(family, 0).shape[0] / tag_border_cells(family)
