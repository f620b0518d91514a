"""Camera images of the lab as an IR camera sees it: dark ground, bright round markers (pure).

Pixel convention (shared with the detector): pixel ``[row, col]`` has its centre at
``(u, v) = (col, row)``, so a marker projected to (u, v) by the camera model is drawn centred
there and its intensity centroid is (u, v).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from common.camera import Intrinsics, Pose, project
from services.sim.robots import MARKER_DIAMETER_MM

MARKER_RADIUS_MM = MARKER_DIAMETER_MM / 2


@dataclass(frozen=True)
class Blob:
    """Something bright in the image: centre (px), semi-axes (px), angle (rad), peak gray."""

    u: float
    v: float
    a_px: float
    b_px: float
    angle_rad: float = 0.0
    peak: float = 255.0
    smear_u: float = 0.0  # how far it moved over the exposure (px); it ends at (u, v)
    smear_v: float = 0.0


@dataclass(frozen=True)
class Glint:
    """A stray reflection on the ground: a world point and its elongated size (mm)."""

    x_mm: float
    y_mm: float
    z_mm: float
    long_mm: float
    short_mm: float
    angle_rad: float


class NoiseBank:
    """Sensor noise for many frames from a few fields drawn once and cycled: a frame's worth
    of normal deviates costs milliseconds, and the detector cannot tell the difference. The
    fields (10 MB for the tracking camera) are drawn at the first frame: the sim's device
    processes build the same lab and never draw a frame."""

    def __init__(self, sigma: float, width: int, height: int, rng: np.random.Generator,
                 fields: int = 8) -> None:
        self._draw = lambda: rng.normal(0.0, sigma, (fields, height, width)).astype(np.float32)
        self._fields: np.ndarray | None = None
        self._next = 0

    def add_to(self, image: np.ndarray) -> None:
        if self._fields is None:
            self._fields = self._draw()
        image += self._fields[self._next]
        self._next = (self._next + 1) % len(self._fields)


def draw(blobs: list[Blob], width: int, height: int, rng: np.random.Generator, *,
         background: float | np.ndarray = 16.0, noise_sigma: float = 2.5,
         noise: NoiseBank | None = None) -> np.ndarray:
    """An 8-bit gray image of ``blobs`` on a background (a gray level, or a picture: float32,
    height × width), with noise (``noise`` if given, else ``noise_sigma`` drawn from ``rng``),
    edges anti-aliased, moving blobs smeared."""
    if isinstance(background, np.ndarray):
        image = background.astype(np.float32, copy=True)
    else:
        image = np.full((height, width), background, dtype=np.float32)
    for blob in blobs:
        _draw_blob(image, blob)
    if noise is not None:
        noise.add_to(image)
    elif noise_sigma > 0:
        image += rng.normal(0.0, noise_sigma, size=image.shape).astype(np.float32)
    np.rint(image, out=image)
    return np.clip(image, 0, 255, out=image).astype(np.uint8)


def _draw_blob(image: np.ndarray, blob: Blob) -> None:
    reach = max(blob.a_px, blob.b_px) + 2
    u_lo, u_hi = min(blob.u, blob.u - blob.smear_u), max(blob.u, blob.u - blob.smear_u)
    v_lo, v_hi = min(blob.v, blob.v - blob.smear_v), max(blob.v, blob.v - blob.smear_v)
    c0, c1 = int(np.floor(u_lo - reach)), int(np.ceil(u_hi + reach)) + 1
    r0, r1 = int(np.floor(v_lo - reach)), int(np.ceil(v_hi + reach)) + 1
    height, width = image.shape
    c0, c1, r0, r1 = max(c0, 0), min(c1, width), max(r0, 0), min(r1, height)
    if c0 >= c1 or r0 >= r1:
        return
    cols, rows = np.meshgrid(np.arange(c0, c1, dtype=float), np.arange(r0, r1, dtype=float))
    samples = max(1, int(np.ceil(np.hypot(blob.smear_u, blob.smear_v) * 2)))
    coverage = np.zeros_like(cols)
    for k in range(samples):  # the exposure, as the mean of where the blob was
        back = (samples - 1 - k) / max(samples - 1, 1) if samples > 1 else 0.0
        coverage += _coverage(cols - (blob.u - back * blob.smear_u),
                              rows - (blob.v - back * blob.smear_v), blob)
    coverage /= samples
    patch = image[r0:r1, c0:c1]
    np.maximum(patch, patch + coverage * (blob.peak - patch), out=patch)


def _coverage(du: np.ndarray, dv: np.ndarray, blob: Blob) -> np.ndarray:
    """How much of each pixel the blob covers, centred at offsets (du, dv): distance to the
    ellipse's edge in pixels (exact for a circle), a 1 px wide soft edge."""
    cos, sin = np.cos(blob.angle_rad), np.sin(blob.angle_rad)
    along, across = du * cos + dv * sin, -du * sin + dv * cos
    scale = min(blob.a_px, blob.b_px)
    rho = np.sqrt((along / blob.a_px) ** 2 + (across / blob.b_px) ** 2)
    return np.clip((1.0 - rho) * scale + 0.5, 0.0, 1.0)


def marker_blobs(points_world: np.ndarray, pose: Pose, intr: Intrinsics, *,
                 radius_mm: float = MARKER_RADIUS_MM, peak: float = 255.0) -> list[Blob]:
    """The discs of spherical markers as a PTZ camera sees them (pinhole, eq. 1–3)."""
    points = np.atleast_2d(points_world)
    uv = project(points, pose, intr)
    depth = pose.to_camera(points)[:, 0]
    blobs = []
    for (u, v), x in zip(uv, depth, strict=True):
        if np.isfinite(u) and x > 0:
            r = max(intr.fy_px * radius_mm / x, 0.6)
            blobs.append(Blob(float(u), float(v), r, r, 0.0, peak))
    return blobs


def glint_blobs(glints: list[Glint], pose: Pose, intr: Intrinsics) -> list[Blob]:
    if not glints:
        return []
    points = np.array([[g.x_mm, g.y_mm, g.z_mm] for g in glints])
    uv = project(points, pose, intr)
    depth = pose.to_camera(points)[:, 0]
    out = []
    for g, (u, v), x in zip(glints, uv, depth, strict=True):
        if np.isfinite(u) and x > 0:
            scale = intr.fy_px / x
            out.append(Blob(float(u), float(v), max(g.long_mm * scale, 1.5),
                            max(g.short_mm * scale, 0.5), g.angle_rad, 235.0))
    return out
