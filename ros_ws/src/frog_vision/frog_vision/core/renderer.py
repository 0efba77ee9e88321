"""The camera simulator: top-down colour frames of the tank with the robot in it.

Each frame is drawn in an ideal (distortion-free) image with the camera's ``K``: a static
background (water, the calibration board) computed once, then the robot (body, limbs, the
real tag texture) in a small region of interest at ``supersample`` x resolution, averaged
over ``blur_samples`` poses spread over the exposure time (motion blur: the robot moves at
its body twist during the exposure), shrunk with area averaging (anti-aliasing). Uneven
lighting multiplies the scene by a smooth gain field; lens distortion is applied by one
remap of the ideal image (its inverse is what the tracker's camera model undoes); sensor
noise is added last. The frame's ground truth is the robot pose at mid-exposure.
"""
from __future__ import annotations

import dataclasses

import cv2
import numpy as np

from frog_vision.core.camera_model import CameraModel
from frog_vision.core.pose import tag_height_setting, tag_size_setting
from frog_vision.core.robot_shape import BODY_FRAME_WIDTH, BODY_SIDE, LIMB_WIDTH, RobotShape, frog_outline
from frog_vision.core.tag_images import FAMILIES, tag_border_cells, tag_image
from frog_vision.core.tank_calibration import Board, CameraPose
from frog_common.se2 import twist_arc
from frog_common.settings import Settings, setting

_CELL_PX = 8           # texture pixels per tag cell
#: Corner jitter that gives the authors' measured pose noise at rest (see RenderSettings).
AUTHORS_CORNER_JITTER_PX = 0.2


@dataclasses.dataclass(frozen=True)
class RenderSettings(Settings):
    """Settings of :class:`TankRenderer`.

    Attributes
    ----------
    tag_family, tag_id, tag_size, tag_height
        The robot's tag (edge of the detected square [m]) and its height over the board [m].
    exposure : float
        Exposure time [s] (motion blur); 0 = instantaneous.
    blur_samples : int
        Poses averaged over the exposure (1 = no blur).
    noise_sigma : float
        Gaussian sensor noise [grey levels of 255].
    brightness : float
        Global gain (1 = well lit, 0.4 = dim).
    lighting : float
        Strength of the uneven lighting: the gain falls by this fraction from the hot spot
        to the darkest corner.
    corner_jitter_px : float
        Per-frame random displacement of the tag's image corners [px RMS]: what a real
        camera adds to the ideal image (vibration, ripples moving the floating robot, rolling
        shutter). A rendered tag is otherwise located to ~0.02 px; 0.2 px (~0.26 mm at the
        default geometry) matches the authors' measured pose noise at rest (0.2-1.3 mm,
        ``hardware_runs/README.md``).
    supersample : int
        Resolution factor of the robot's region (anti-aliasing).
    drop_probability : float
        Chance that a frame is lost (the camera sim publishes nothing).
    seed : int
        Of the noise, frame drops and the water texture.
    """

    tag_family: str = setting("tagStandard41h12", "AprilTag family of the robot's tag", choices=FAMILIES)
    tag_id: int = setting(47, "id of the robot's tag (other ids are ignored)", min=0, max=100000)
    tag_size: float = tag_size_setting()
    tag_height: float = tag_height_setting()
    exposure: float = setting(0.010, "exposure time (motion blur)", min=0.0, max=0.2, unit="s")
    blur_samples: int = setting(5, "poses averaged over the exposure", min=1, max=32)
    noise_sigma: float = setting(2.0, "sensor noise", min=0.0, max=50.0, unit="grey levels")
    brightness: float = setting(1.0, "global lighting gain", min=0.05, max=2.0)
    lighting: float = setting(0.3, "uneven lighting: gain drop from the hot spot to the darkest corner",
                              min=0.0, max=0.99)
    corner_jitter_px: float = setting(0.0, "per-frame random tag displacement (vibration, ripples); "
                                      f"{AUTHORS_CORNER_JITTER_PX} gives the authors' measured pose noise, "
                                      "0 = an ideal camera", min=0.0, max=5.0, unit="px")
    supersample: int = setting(2, "resolution factor of the robot's region (anti-aliasing)", min=1, max=4)
    drop_probability: float = setting(0.0, "chance that a frame is lost", min=0.0, max=0.99, live=True)
    seed: int = setting(0, "random seed (noise, drops, water texture)", min=0, max=2**31 - 1)


@dataclasses.dataclass(frozen=True)
class Occluder:
    """A dark disc (a hand, a net) at (x, y) [m] with ``radius`` [m], seen in the z = 0 plane."""

    x: float
    y: float
    radius: float


class TankRenderer:
    """Render frames of the tank (see the module docstring).

    Parameters
    ----------
    camera : CameraModel
    camera_pose : CameraPose
    settings : RenderSettings
    board : Board or None
        The calibration board drawn on the tank plane (default board when ``None``;
        ``Board(...)`` with no tags is not allowed, pass ``draw_board=False``).
    """

    def __init__(self, camera: CameraModel, camera_pose: CameraPose, settings: RenderSettings | None = None,
                 board: Board | None = None, draw_board: bool = True):
        self.camera = camera
        self.camera_pose = camera_pose
        self.settings = s = settings or RenderSettings()
        self.board = board if board is not None else Board.from_yaml()
        self.rng = np.random.default_rng(s.seed)
        w, h = camera.width, camera.height
        self._H0 = self._plane_homography(0.0)
        self._Htag = self._plane_homography(s.tag_height)
        self._background = self._draw_background(draw_board)          # float32, unlit
        self._gain = self._lighting_field()                            # float32 (h, w)
        lit = self._background * self._gain[..., None]
        self._background_lit = np.clip(lit, 0, 255).astype(np.uint8)
        self._tag_texture, self._tag_affine = self._texture(s.tag_family, s.tag_id, s.tag_size)
        self._maps = self._distortion_maps() if camera.has_distortion else None
        self._noise = np.empty((h, w, 3), np.int16)
        self._default_shape = frog_outline()

    # -- static parts ----------------------------------------------------------------------
    def _plane_homography(self, z: float) -> np.ndarray:
        """Tank plane z: (x, y, 1) -> ideal pixel (u, v, 1)."""
        r_ct = self.camera_pose.rotation.T
        t = -r_ct @ self.camera_pose.position
        m = np.column_stack([r_ct[:, 0], r_ct[:, 1], r_ct[:, 2] * z + t])
        return self.camera.K @ m

    @staticmethod
    def _texture(family: str, tag_id: int, size: float):
        """Tag texture (grey, white margin of one cell) and the affine map texture px -> tag
        frame [m]."""
        img = tag_image(family, tag_id)
        img = np.pad(img, 1, constant_values=255)
        n = img.shape[0]
        cell = size / tag_border_cells(family)
        tex = np.repeat(np.repeat(img, _CELL_PX, 0), _CELL_PX, 1)
        tex = np.where(tex > 127, 225, 25).astype(np.uint8)      # printed paper and ink
        k = cell / _CELL_PX
        # texel centre i -> x = ((i + 0.5) / CELL - n / 2) * cell ; rows go down = -y
        affine = np.array([[k, 0, (0.5 / _CELL_PX - n / 2) * cell],
                           [0, -k, -(0.5 / _CELL_PX - n / 2) * cell],
                           [0, 0, 1.0]])
        return tex, affine

    def _draw_background(self, draw_board: bool) -> np.ndarray:
        w, h = self.camera.width, self.camera.height
        rng = np.random.default_rng(self.settings.seed + 1)
        # water over a light tank floor: smooth low-frequency texture
        low = rng.normal(size=(h // 40 + 2, w // 40 + 2)).astype(np.float32)
        tex = cv2.resize(low, (w, h), interpolation=cv2.INTER_CUBIC)
        base = np.array([165.0, 150.0, 120.0], np.float32)              # BGR: blue-grey water
        bg = base[None, None, :] + 6.0 * tex[..., None]
        if draw_board:
            for t in self.board.tags:
                img, affine = self._texture(self.board.family, t.tag_id, t.size)
                c, s = np.cos(t.yaw), np.sin(t.yaw)
                place = np.array([[c, -s, t.x], [s, c, t.y], [0, 0, 1.0]])
                H = self._H0 @ place @ affine
                warped = cv2.warpPerspective(img, H, (w, h), flags=cv2.INTER_LINEAR,
                                             borderMode=cv2.BORDER_CONSTANT, borderValue=0)
                mask = cv2.warpPerspective(np.full_like(img, 255), H, (w, h), flags=cv2.INTER_LINEAR)
                a = (mask.astype(np.float32) / 255.0)[..., None]
                bg = bg * (1 - a) + warped.astype(np.float32)[..., None] * a
        return bg.astype(np.float32)

    def _lighting_field(self) -> np.ndarray:
        w, h = self.camera.width, self.camera.height
        s = self.settings
        rng = np.random.default_rng(self.settings.seed + 2)
        hot = np.array([w * rng.uniform(0.3, 0.7), h * rng.uniform(0.3, 0.7)])
        yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
        r2 = ((xx - hot[0]) ** 2 + (yy - hot[1]) ** 2)
        r2 /= r2.max()
        return (s.brightness * (1.0 - s.lighting * r2)).astype(np.float32)

    def _distortion_maps(self):
        """For each distorted pixel, where it looks in the ideal image."""
        w, h = self.camera.width, self.camera.height
        yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
        ideal = self.camera.undistort_pixels(np.column_stack([xx.ravel(), yy.ravel()]))
        mx = ideal[:, 0].reshape(h, w).astype(np.float32)
        my = ideal[:, 1].reshape(h, w).astype(np.float32)
        return cv2.convertMaps(mx, my, cv2.CV_16SC2)

    # -- per frame ---------------------------------------------------------------------------
    def should_drop(self) -> bool:
        """Draw whether the next frame is lost."""
        return bool(self.settings.drop_probability > 0 and self.rng.random() < self.settings.drop_probability)

    def render(self, pose, twist=(0.0, 0.0, 0.0), shape: RobotShape | None = None,
               tag_offset=None, occluders=()) -> np.ndarray:
        """One BGR frame (uint8, camera size) with the robot's body frame at ``pose``.

        Parameters
        ----------
        pose : (x, y, heading)
            Body frame at mid-exposure [m, m, rad].
        twist : (forward, lateral, yaw rate)
            Body-frame velocity during the exposure [m/s, m/s, rad/s].
        shape : RobotShape, optional
            Body-frame outline (default: :func:`frog_outline`).
        tag_offset : (x, y, yaw), optional
            The tag's pose in the body frame (default: at the ring centre, aligned).
        occluders : sequence of Occluder
        """
        s = self.settings
        shape = self._default_shape if shape is None else shape
        if tag_offset is None:
            c = shape.ring_centre
            tag_offset = (float(c[0]), float(c[1]), 0.0)
        n = int(s.blur_samples) if s.exposure > 0 else 1
        taus = (np.linspace(-0.5, 0.5, n) * s.exposure) if n > 1 else np.zeros(1)
        poses = [twist_arc(pose, twist, float(t)) for t in taus]
        frame = self._background_lit.copy()
        self._draw_robot(frame, poses, shape, tag_offset)
        for occ in occluders:
            self._draw_occluder(frame, occ)
        if self._maps is not None:
            frame = cv2.remap(frame, self._maps[0], self._maps[1], cv2.INTER_LINEAR,
                              borderMode=cv2.BORDER_REPLICATE)
        if s.noise_sigma > 0:
            cv2.randn(self._noise, 0, s.noise_sigma)
            frame = cv2.add(frame, self._noise, dtype=cv2.CV_8U)
        return frame

    def _project(self, H, pts) -> np.ndarray:
        p = np.column_stack([pts, np.ones(len(pts))]) @ H.T
        return p[:, :2] / p[:, 2:3]

    def _draw_robot(self, frame, poses, shape: RobotShape, tag_offset) -> None:
        s = self.settings
        w, h = self.camera.width, self.camera.height
        ss = int(s.supersample)
        # body outline: the ring widened to the frame's outer edge
        centre = shape.ring_centre
        body_local = centre + (shape.ring - centre) * (1 + BODY_FRAME_WIDTH / BODY_SIDE)
        world = [shape.transformed(p) for p in poses]
        bodies = [RobotShape(body_local, shape.limbs).transformed(p).ring for p in poses]
        allpts = np.concatenate([np.concatenate([b, ws.limbs.reshape(-1, 2)]) for b, ws in zip(bodies, world)])
        uv = self._project(self._H0, allpts)
        margin = 4
        x0, y0 = np.floor(uv.min(axis=0)).astype(int) - margin
        x1, y1 = np.ceil(uv.max(axis=0)).astype(int) + margin
        x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, w), min(y1, h)
        if x1 <= x0 or y1 <= y0:
            return                                      # robot out of view
        rw, rh = x1 - x0, y1 - y0
        # ROI pixel (supersampled) q = (p - origin + 0.5) * ss - 0.5
        to_roi = np.array([[ss, 0, (0.5 - x0) * ss - 0.5], [0, ss, (0.5 - y0) * ss - 0.5], [0, 0, 1.0]])
        bg = cv2.resize(self._background[y0:y1, x0:x1], (rw * ss, rh * ss), interpolation=cv2.INTER_LINEAR)
        acc = np.zeros_like(bg)
        shift = 4
        sc = float(1 << shift)
        jitter = (self.rng.normal(0, s.corner_jitter_px * ss, (4, 2)).astype(np.float32)
                  if s.corner_jitter_px > 0 else None)
        n_tex = self._tag_texture.shape[0]
        tex_corners = np.array([[-0.5, -0.5], [n_tex - 0.5, -0.5], [n_tex - 0.5, n_tex - 0.5],
                                [-0.5, n_tex - 0.5]], np.float32)
        limb_px = max(1, int(round(LIMB_WIDTH * self.camera.K[0, 0] / self.camera_pose.position[2] * ss)))
        for pose, body, ws in zip(poses, bodies, world):
            layer = bg.copy()
            Hr = to_roi @ self._H0
            poly = np.round(self._project(Hr, body) * sc).astype(np.int32)
            cv2.fillPoly(layer, [poly], (95.0, 120.0, 105.0), cv2.LINE_AA, shift)   # silicone body
            if len(ws.limbs):
                seg = np.round(self._project(Hr, ws.limbs.reshape(-1, 2)) * sc).astype(np.int32).reshape(-1, 2, 2)
                cv2.polylines(layer, list(seg), False, (40.0, 150.0, 60.0), limb_px, cv2.LINE_AA, shift)
            c, sn = np.cos(pose[2]), np.sin(pose[2])
            body_to_tank = np.array([[c, -sn, pose[0]], [sn, c, pose[1]], [0, 0, 1.0]])
            ox, oy, oa = tag_offset
            co, so = np.cos(oa), np.sin(oa)
            tag_to_body = np.array([[co, -so, ox], [so, co, oy], [0, 0, 1.0]])
            H = to_roi @ self._Htag @ body_to_tank @ tag_to_body @ self._tag_affine
            if jitter is not None:
                dst = self._project(H, tex_corners).astype(np.float32) + jitter
                H = cv2.getPerspectiveTransform(tex_corners, dst)
            tex = cv2.cvtColor(self._tag_texture, cv2.COLOR_GRAY2BGR).astype(np.float32)
            cv2.warpPerspective(tex, H, (rw * ss, rh * ss), dst=layer, flags=cv2.INTER_LINEAR,
                                borderMode=cv2.BORDER_TRANSPARENT)
            acc += layer
        acc *= 1.0 / len(poses)
        small = cv2.resize(acc, (rw, rh), interpolation=cv2.INTER_AREA) if ss > 1 else acc
        small *= self._gain[y0:y1, x0:x1, None]
        frame[y0:y1, x0:x1] = np.clip(small, 0, 255).astype(np.uint8)

    def _draw_occluder(self, frame, occ: Occluder) -> None:
        ang = np.linspace(0, 2 * np.pi, 48, endpoint=False)
        pts = np.column_stack([occ.x + occ.radius * np.cos(ang), occ.y + occ.radius * np.sin(ang)])
        uv = np.round(self._project(self._H0, pts) * 16).astype(np.int32)
        cv2.fillPoly(frame, [uv], (40, 45, 50), cv2.LINE_AA, 4)

    def project_tag_corners(self, pose, tag_offset=None) -> np.ndarray:
        """Exact pixel positions (distorted image) of the tag's detected corners (4, 2)
        (``tag_offset`` as in :meth:`render`; default: the default outline's ring centre)."""
        if tag_offset is None:
            c = self._default_shape.ring_centre
            tag_offset = (float(c[0]), float(c[1]), 0.0)
        from frog_vision.core.detection import TAG_CORNERS_UNIT
        from frog_vision.core.pose import compose_offset
        tp, _ = compose_offset(pose, tag_offset)
        c, s = np.cos(tp[2]), np.sin(tp[2])
        local = TAG_CORNERS_UNIT * self.settings.tag_size / 2
        xy = local @ np.array([[c, s], [-s, c]]) + tp[:2]
        pts = np.column_stack([xy, np.full(4, self.settings.tag_height)])
        return self.camera_pose.project(self.camera, pts)
