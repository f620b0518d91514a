"""What a PTZ camera sees of the lab, for people to look at (pure): the crater's surface
through the camera model, shaded from the height map, and the robot's body.

Each pixel's ray is followed to where it meets the height map (a few fixed-point steps from
the floor's height; rays that do not come down are the hall, dark). The surface is lit from
above and one side (Lambert) on a speckled regolith; with the IR-cut filter on the picture
is the day view, with it off the IR view (the ground dim under the IR light, the markers
bright: they are drawn on top by ``render.marker_blobs``, exactly where the camera model puts
them, so the pictures do not move a marker by a pixel). The ground is computed at half the
resolution and scaled up; a camera that has not moved since the last picture reuses it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import cv2
import numpy as np

from common.camera import Intrinsics, Pose, project, rot_z
from common.heightmap import HeightMap
from common.lens import undistort

LIGHT = np.array([0.35, -0.45, 0.82]) / np.linalg.norm([0.35, -0.45, 0.82])
HALL = 0.12  # brightness of what is not the crater (walls, the hall above)
STEPS = 5  # fixed-point steps from the floor to the surface along a ray
ROBOT_SIZE_MM = (420.0, 280.0)  # the chassis' length and width under its marker
ROBOT_GAP_MM = 20.0  # from the chassis' top to the marker's centre


@dataclass(frozen=True)
class Look:
    """How the picture is exposed: brightness of the ground's darkest and brightest shade,
    of the robot's chassis, and the markers' peak."""

    ground_lo: float
    ground_hi: float
    chassis: float
    marker_peak: float


# Day: the brightest ground and the markers stay below the detector's lowest threshold (203),
# so a day picture shows no marker to it (the IR-lit ones are what it finds).
DAY = Look(ground_lo=40.0, ground_hi=175.0, chassis=30.0, marker_peak=165.0)
INFRARED = Look(ground_lo=10.0, ground_hi=70.0, chassis=8.0, marker_peak=255.0)


def shading(crater: HeightMap, seed: int = 0) -> np.ndarray:
    """Brightness 0…1 of every grid point of the crater: Lambert under ``LIGHT`` on a
    regolith whose albedo varies a little from place to place."""
    gy, gx = np.gradient(crater.heights_mm.astype(np.float64), crater.resolution_mm)
    normal = np.dstack([-gx, -gy, np.ones_like(gx)])
    normal /= np.linalg.norm(normal, axis=2, keepdims=True)
    lambert = np.clip(normal @ LIGHT, 0.0, 1.0)
    rng = np.random.default_rng((seed, 23))
    albedo = 0.8 + 0.2 * cv2.GaussianBlur(rng.random(lambert.shape).astype(np.float32),
                                          (0, 0), 1.5)
    return (0.15 + 0.85 * lambert * albedo).astype(np.float32)


@dataclass
class GroundView:
    """The crater as seen by one camera; the last picture is kept for a camera standing
    still."""

    crater: HeightMap
    shade: np.ndarray
    _last_key: tuple | None = None
    _last: np.ndarray | None = field(default=None, repr=False)

    @classmethod
    def of(cls, crater: HeightMap, seed: int = 0) -> GroundView:
        return cls(crater, shading(crater, seed))

    def brightness(self, pose: Pose, intr: Intrinsics) -> np.ndarray:
        """Brightness 0…1 of every pixel (height × width), float32."""
        key = (pose, intr)
        if key != self._last_key or self._last is None:
            self._last, self._last_key = self._render(pose, intr), key
        return self._last

    def _render(self, pose: Pose, intr: Intrinsics) -> np.ndarray:
        across, down_the_image = _directions(intr)
        rays = np.dstack([np.ones_like(across), across, down_the_image]) \
            @ pose.rotation.T.astype(np.float32)
        origin = pose.position.astype(np.float32)
        down = rays[..., 2] < -1e-3
        dz = np.where(down, rays[..., 2], -1.0)
        c = self.crater
        floor = float(np.min(c.heights_mm))
        height = np.full(across.shape, floor, np.float32)
        for _ in range(STEPS):
            s = (height - origin[2]) / dz
            col = (origin[0] + s * rays[..., 0] - c.origin_x_mm) / c.resolution_mm
            row = (origin[1] + s * rays[..., 1] - c.origin_y_mm) / c.resolution_mm
            height = np.asarray(cv2.remap(c.heights_mm, col, row, cv2.INTER_LINEAR,
                                          borderMode=cv2.BORDER_REPLICATE), np.float32)
        bright = cv2.remap(self.shade, col, row, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                           borderValue=HALL)
        bright[~down] = HALL
        return cv2.resize(bright, (intr.width_px, intr.height_px),
                          interpolation=cv2.INTER_LINEAR)


@lru_cache(maxsize=32)
def _directions(intr: Intrinsics) -> tuple[np.ndarray, np.ndarray]:
    """The normalised direction (y/x, z/x in the camera frame) each pixel of a half-size
    picture looks along: through the lens's distortion, undone (zooming changes it)."""
    w, h = (intr.width_px + 1) // 2, (intr.height_px + 1) // 2
    u = (np.arange(w, dtype=np.float64) + 0.5) * intr.width_px / w - 0.5
    v = (np.arange(h, dtype=np.float64) + 0.5) * intr.height_px / h - 0.5
    uu, vv = np.meshgrid(u, v)
    straight = undistort(np.column_stack([((uu - intr.cy_px) / intr.fy_px).ravel(),
                                          ((vv - intr.cz_px) / intr.fz_px).ravel()]),
                         intr.distortion)
    return (straight[:, 0].reshape(uu.shape).astype(np.float32),
            straight[:, 1].reshape(uu.shape).astype(np.float32))


def chassis_outline(marker_mm: np.ndarray, heading_rad: float, ground_mm: float, pose: Pose,
                    intr: Intrinsics) -> np.ndarray | None:
    """The robot's chassis (a box under its marker, turned to its heading) as an image
    polygon (the hull of its corners), or None when it is behind the camera."""
    length, width = ROBOT_SIZE_MM
    top = float(marker_mm[2]) - ROBOT_GAP_MM
    bottom = min(ground_mm, top - 1.0)
    corners = np.array([[sx * length / 2, sy * width / 2, z] for sx in (-1, 1)
                        for sy in (-1, 1) for z in (bottom, top)])
    corners[:, :2] = corners[:, :2] @ rot_z(heading_rad)[:2, :2].T + marker_mm[:2]
    uv = project(corners, pose, intr)
    if not np.all(np.isfinite(uv)):
        return None
    return cv2.convexHull(np.round(uv * 16).astype(np.int32))


def compose(ground: np.ndarray, look: Look, chassis: list[np.ndarray]) -> np.ndarray:
    """The picture before markers and noise: the ground in ``look``'s shades, the chassis on
    it (float32 gray levels)."""
    image = look.ground_lo + ground * (look.ground_hi - look.ground_lo)
    for hull in chassis:
        cv2.fillConvexPoly(image, hull, look.chassis, lineType=cv2.LINE_AA, shift=4)
    return image
