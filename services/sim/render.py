"""Camera images of the lab as an IR camera sees it: dark ground, bright round markers (pure).

Pixel convention (shared with the detector): pixel ``[row, col]`` has its centre at
``(u, v) = (col, row)``, so a marker projected to (u, v) by the camera model is drawn centred
there and its intensity centroid is (u, v).
"""

from __future__ import annotations

import math
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
    processes build the same lab and never draw a frame. On a uniform background each field
    is also kept as a finished 8-bit picture, so that a frame costs a copy and its blobs'
    patches."""

    def __init__(self, sigma: float, width: int, height: int, rng: np.random.Generator,
                 fields: int = 8, whole: bool = False) -> None:
        """``whole``: the deviates rounded to whole gray levels and kept as bytes (a quarter
        of the memory: for large pictures that are rounded to 8 bits anyway)."""
        self._draw = (lambda: np.clip(np.rint(rng.normal(0.0, sigma, (fields, height, width))),
                                      -127, 127).astype(np.int8)) if whole else (
            lambda: rng.normal(0.0, sigma, (fields, height, width)).astype(np.float32))
        self._fields: np.ndarray | None = None
        self._baked: dict[tuple[int, float], np.ndarray] = {}
        self._next = 0

    def take(self) -> np.ndarray:
        """The next field (height × width, float32)."""
        if self._fields is None:
            self._fields = self._draw()
        index = self._next
        self._next = (self._next + 1) % len(self._fields)
        return self._fields[index]

    def add_to(self, image: np.ndarray) -> None:
        image += self.take()

    def on(self, background: float) -> tuple[np.ndarray, np.ndarray]:
        """The next field, and a copy of it on ``background`` as the 8-bit picture."""
        index = self._next
        field = self.take()
        baked = self._baked.get((index, background))
        if baked is None:
            baked = self._baked[(index, background)] = _to_gray(field + np.float32(background))
        return field, baked.copy()


def draw(blobs: list[Blob], width: int, height: int, rng: np.random.Generator, *,
         background: float | np.ndarray = 16.0, noise_sigma: float = 2.5,
         noise: NoiseBank | None = None) -> np.ndarray:
    """An 8-bit gray image of ``blobs`` on a background (a gray level, or a picture: float32,
    height × width), with noise (``noise`` if given, else ``noise_sigma`` drawn from ``rng``),
    edges anti-aliased, moving blobs smeared."""
    if noise is not None and not isinstance(background, np.ndarray):
        return _on_uniform(blobs, width, height, float(background), noise)
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
    return _to_gray(image)


def _to_gray(image: np.ndarray) -> np.ndarray:
    np.rint(image, out=image)
    np.maximum(image, 0.0, out=image)  # the ufuncs: np.clip's own checks cost more here
    return np.minimum(image, 255.0, out=image).astype(np.uint8)


def _on_uniform(blobs: list[Blob], width: int, height: int, background: float,
                noise: NoiseBank) -> np.ndarray:
    """``draw`` on a uniform background: the noise field's finished picture, and only the
    blobs' patches drawn again — each with every blob that reaches into it, in order, so that
    overlapping blobs come out as on a whole canvas."""
    field, image = noise.on(background)
    boxes = [_box(blob, width, height) for blob in blobs]
    for box in boxes:
        if box is None:
            continue
        r0, r1, c0, c1 = box
        canvas = np.full((r1 - r0, c1 - c0), background, dtype=np.float32)
        for blob, other in zip(blobs, boxes, strict=True):
            if other is not None and other[0] < r1 and r0 < other[1] and other[2] < c1 \
                    and c0 < other[3]:
                _draw_blob(canvas, blob, origin=(r0, c0), box=other)
        canvas += field[r0:r1, c0:c1]
        image[r0:r1, c0:c1] = _to_gray(canvas)
    return image


def _box(blob: Blob, width: int, height: int) -> tuple[int, int, int, int] | None:
    """The pixels (rows r0:r1, columns c0:c1) a blob may touch over its exposure, or None."""
    reach = max(blob.a_px, blob.b_px) + 2
    u_lo, u_hi = min(blob.u, blob.u - blob.smear_u), max(blob.u, blob.u - blob.smear_u)
    v_lo, v_hi = min(blob.v, blob.v - blob.smear_v), max(blob.v, blob.v - blob.smear_v)
    if not all(map(math.isfinite, (u_lo, u_hi, v_lo, v_hi, reach))):
        return None
    c0, c1 = max(math.floor(u_lo - reach), 0), min(math.ceil(u_hi + reach) + 1, width)
    r0, r1 = max(math.floor(v_lo - reach), 0), min(math.ceil(v_hi + reach) + 1, height)
    return None if c0 >= c1 or r0 >= r1 else (r0, r1, c0, c1)


def _draw_blob(image: np.ndarray, blob: Blob, origin: tuple[int, int] = (0, 0),
               box: tuple[int, int, int, int] | None = None) -> None:
    """``blob`` onto ``image``, whose pixel [0, 0] is the picture's ``origin`` (row, column);
    ``box``: the blob's ``_box`` in the picture, if known."""
    height, width = image.shape
    if box is None:
        box = _box(blob, origin[1] + width, origin[0] + height)
        if box is None:
            return
    r0, r1 = max(box[0], origin[0]), min(box[1], origin[0] + height)
    c0, c1 = max(box[2], origin[1]), min(box[3], origin[1] + width)
    if c0 >= c1 or r0 >= r1:
        return
    cols = np.arange(c0, c1, dtype=float)[None, :]
    rows = np.arange(r0, r1, dtype=float)[:, None]
    samples = max(1, math.ceil(math.hypot(blob.smear_u, blob.smear_v) * 2))
    coverage = _coverage(cols - blob.u, rows - blob.v, blob)
    for k in range(samples - 1):  # the exposure, as the mean of where the blob was
        back = (samples - 1 - k) / (samples - 1)
        coverage += _coverage(cols - (blob.u - back * blob.smear_u),
                              rows - (blob.v - back * blob.smear_v), blob)
    if samples > 1:
        coverage /= samples
    patch = image[r0 - origin[0]:r1 - origin[0], c0 - origin[1]:c1 - origin[1]]
    np.maximum(patch, patch + coverage * (blob.peak - patch), out=patch)


def _coverage(du: np.ndarray, dv: np.ndarray, blob: Blob) -> np.ndarray:
    """How much of each pixel the blob covers, centred at offsets (du, dv) — a row and a column
    of offsets: distance to the ellipse's edge in pixels (exact for a circle), a 1 px wide
    soft edge. The ellipse as its quadratic form (rho² = A du² + B du dv + C dv²), so that
    only a few operations span the whole patch."""
    scale = min(blob.a_px, blob.b_px)
    if blob.a_px == blob.b_px:  # a disc: no need to turn it
        k = 1.0 / (blob.a_px * blob.a_px)
        rho2 = du * du * k + dv * dv * k
    else:
        cos, sin = math.cos(blob.angle_rad), math.sin(blob.angle_rad)
        ia, ib = 1.0 / (blob.a_px * blob.a_px), 1.0 / (blob.b_px * blob.b_px)
        a = cos * cos * ia + sin * sin * ib
        b = 2.0 * cos * sin * (ia - ib)
        c = sin * sin * ia + cos * cos * ib
        rho2 = du * du * a + dv * dv * c
        rho2 += (du * b) * dv
    rho = np.sqrt(rho2, out=rho2)
    rho *= -scale
    rho += scale + 0.5
    np.maximum(rho, 0.0, out=rho)
    return np.minimum(rho, 1.0, out=rho)


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
