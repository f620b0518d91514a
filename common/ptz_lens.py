"""A PTZ camera's zoom lens (pure): the VAPIX zoom step → focal length curve and the lens's
distortion as a function of focal length, in pixels of the camera's picture (no chip size:
what calibration measures is where things land in the picture).

VAPIX reports a zoom *step* (1–9999), never a focal length, and a real zoom curve is far from
straight: it must be measured (``stb calib collect --zooms``). A curve through measured points
is interpolated by PCHIP (monotone, no overshoot between the points: a longer step never gives
a shorter focal length); outside the measured steps it holds the nearest end. Distortion
(OpenCV's k1, k2, p1, p2, k3 on normalised coordinates, ``common.lens``) is measured at some
focal lengths and interpolated linearly between them by focal length, holding the ends. The
focal lengths are pixels of the picture the lens was measured in (``PtzLens.width_px``); a
picture of another size scales them.

``STRAIGHT_LINE`` is what a camera calibrated at one zoom uses: the AXIS 215's 3.8–46 mm
(data sheet, the paper's Table 1) spread evenly over steps 1–9999, no distortion, in pixels
of its 704 × 576 picture of a 3.6 × 2.7 mm chip.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np

from common.camera import Intrinsics
from common.data_sheet import (
    AXIS_215_CHIP_MM,
    AXIS_215_FOCAL_MM,
    AXIS_215_PICTURE_PX,
    AXIS_215_PX_PER_MM,
    AXIS_215_ZOOM_STEPS,
)
from common.lens import NO_DISTORTION
from common.messages import CameraPose

Distortion = tuple[float, float, float, float, float]


def _monotone_cubic(x: np.ndarray, y: np.ndarray) -> Callable[[np.ndarray | float], np.ndarray]:
    from scipy.interpolate import PchipInterpolator  # only when a curve has 3 points or more

    return PchipInterpolator(x, y, extrapolate=False)


def axis_215(focal_mm: float, **rest: Any) -> Intrinsics:
    """The AXIS 215's picture (704 × 576 of its 3.6 × 2.7 mm chip, Table 1) at a focal length
    in mm."""
    return Intrinsics.from_chip(focal_mm, AXIS_215_CHIP_MM, *AXIS_215_PICTURE_PX, **rest)


def axis_215_px(focal_mm: float) -> float:
    """A focal length of the AXIS 215 in pixels of its 704-wide picture."""
    return focal_mm * AXIS_215_PX_PER_MM


@dataclass(frozen=True)
class ZoomCurve:
    """Focal length at zoom steps, both strictly increasing (pixels for the code's lens, mm
    for a data sheet's or the sim's truth: the curve does not mind)."""

    zooms: tuple[float, ...]
    focals: tuple[float, ...]

    def __post_init__(self) -> None:
        z, f = np.asarray(self.zooms, float), np.asarray(self.focals, float)
        if len(z) < 2 or len(z) != len(f):
            raise ValueError("a zoom curve needs two or more (zoom, focal) points")
        if np.any(np.diff(z) <= 0) or np.any(np.diff(f) <= 0):
            raise ValueError("a zoom curve's zoom steps and focal lengths must both increase: "
                             f"{list(zip(self.zooms, self.focals, strict=True))}")
        if f[0] <= 0:
            raise ValueError(f"a focal length must be positive, not {f[0]}")

    @classmethod
    def of(cls, points: Sequence[Sequence[float]]) -> ZoomCurve:
        """From ``[[zoom, focal], ...]`` (a lab file's table), sorted by zoom."""
        ordered = sorted((float(z), float(f)) for z, f in points)
        return cls(tuple(z for z, _ in ordered), tuple(f for _, f in ordered))

    @cached_property
    def _forward(self) -> Callable[[np.ndarray | float], np.ndarray]:
        """Zoom → focal length between the points: a line through two, PCHIP through more
        (scipy only then: a camera on the data sheet's line does without it)."""
        zooms, focals = np.asarray(self.zooms), np.asarray(self.focals)
        if len(zooms) == 2:
            return lambda z: np.interp(z, zooms, focals)
        return _monotone_cubic(zooms, focals)

    @cached_property
    def _steps(self) -> tuple[np.ndarray, np.ndarray]:
        """Every whole zoom step of the curve and its focal length (increasing both)."""
        steps = np.arange(np.ceil(self.zooms[0]), np.floor(self.zooms[-1]) + 1)
        return steps, np.asarray(self._forward(steps), dtype=float)

    def focal(self, zoom: float) -> float:
        return float(self._forward(min(max(float(zoom), self.zooms[0]), self.zooms[-1])))

    def zoom_for_focal(self, focal: float) -> int:
        """The whole zoom step whose focal length is nearest to ``focal`` (the curve's own
        inverse; clamped to its steps)."""
        steps, focals = self._steps
        i = int(np.clip(np.searchsorted(focals, focal), 1, len(steps) - 1))
        nearer = i if abs(focals[i] - focal) < abs(focals[i - 1] - focal) else i - 1
        return int(steps[nearer])

    def points(self) -> list[tuple[float, float]]:
        return [(z, f) for z, f in zip(self.zooms, self.focals, strict=True)]

    def scaled(self, factor: float) -> ZoomCurve:
        """The same curve with every focal length times ``factor`` (another unit)."""
        return ZoomCurve(self.zooms, tuple(f * factor for f in self.focals))


DATA_SHEET_MM = ZoomCurve(tuple(float(z) for z in AXIS_215_ZOOM_STEPS), AXIS_215_FOCAL_MM)
STRAIGHT_LINE = DATA_SHEET_MM.scaled(axis_215_px(1.0))


def straight_line(width_px: int) -> ZoomCurve:
    """The data sheet's straight line in pixels of a picture ``width_px`` wide (for a camera
    that is not an AXIS 215 only a start: calibration measures its own)."""
    return STRAIGHT_LINE.scaled(width_px / AXIS_215_PICTURE_PX[0])


@dataclass(frozen=True)
class PtzLens:
    """A zoom lens in pixels of a ``width_px`` × ``height_px`` picture: its zoom curve, its
    distortion at some focal lengths, its pixels' aspect (None: as the picture's size has it)
    and its principal point (None: the picture's centre)."""

    curve: ZoomCurve = STRAIGHT_LINE
    distortion_focals_px: tuple[float, ...] = ()
    distortions: tuple[Distortion, ...] = field(default=())
    width_px: int = AXIS_215_PICTURE_PX[0]
    height_px: int = AXIS_215_PICTURE_PX[1]
    pixel_aspect: float | None = None
    principal_px: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        if len(self.distortion_focals_px) != len(self.distortions):
            raise ValueError("one distortion per focal length it was measured at")
        if any(len(d) != 5 for d in self.distortions):
            raise ValueError("a distortion is five coefficients: k1, k2, p1, p2, k3")
        if np.any(np.diff(self.distortion_focals_px) <= 0):
            raise ValueError("distortions must be listed by increasing focal length")

    def focal_px(self, zoom: float) -> float:
        """The focal length at ``zoom`` in pixels of the lens's own picture."""
        return self.curve.focal(zoom)

    def zoom_for_focal(self, focal_px: float) -> int:
        return self.curve.zoom_for_focal(focal_px)

    def distortion(self, focal_px: float) -> Distortion:
        """k1, k2, p1, p2, k3 at ``focal_px``: linear in focal length between the measured
        ones, the nearest held beyond them."""
        if not self.distortions:
            return NO_DISTORTION
        table = np.asarray(self.distortions, dtype=float)
        d = [float(np.interp(focal_px, self.distortion_focals_px, table[:, i]))
             for i in range(5)]
        return (d[0], d[1], d[2], d[3], d[4])

    def intrinsics(self, zoom: float, width_px: int | None = None,
                   height_px: int | None = None) -> Intrinsics:
        """The camera at ``zoom`` in a picture of this size (default the lens's own; another
        size of the same picture scales the focal length and the principal point)."""
        width, height = width_px or self.width_px, height_px or self.height_px
        focal = self.focal_px(zoom)
        scale = width / self.width_px
        principal = None if self.principal_px is None else (
            self.principal_px[0] * scale, self.principal_px[1] * height / self.height_px)
        aspect = self.pixel_aspect if self.pixel_aspect is None or (width, height) == (
            self.width_px, self.height_px) else self.pixel_aspect * (
            height / self.height_px) / scale
        return Intrinsics(focal * scale, width, height, aspect, principal,
                          self.distortion(focal))

    def half_view_deg(self, zoom: float) -> float:
        """Half the picture's height as an angle at ``zoom``."""
        intr = self.intrinsics(zoom)
        return math.degrees(math.atan(intr.height_px / 2 / intr.fz_px))

    def zoom_for_view(self, half_height_deg: float) -> int:
        """The whole zoom step at which half the picture's height spans ``half_height_deg``
        (the nearest; clamped to the curve's steps)."""
        along_height = self.height_px / 2 / math.tan(math.radians(half_height_deg))
        per_focal = self.intrinsics(self.curve.zooms[0]).with_focal(1.0).fz_px
        return self.zoom_for_focal(along_height / per_focal)

    @property
    def measured(self) -> bool:
        """False for the straight-line default (a camera calibrated at one zoom)."""
        return self.curve != straight_line(self.width_px) or bool(self.distortions)


def measured_lens(points: Sequence[tuple[int, float, Sequence[float]]], **picture: Any
                  ) -> PtzLens:
    """The lens from (zoom, focal_px, distortion) measured at two or more zoom steps; fewer:
    the straight-line default (a camera calibrated at one zoom). ``picture``: the lens's
    ``width_px``, ``height_px``, ``pixel_aspect``, ``principal_px``."""
    ordered = sorted(points, key=lambda p: p[0])
    if len(ordered) < 2:
        return PtzLens(straight_line(picture.get("width_px", AXIS_215_PICTURE_PX[0])),
                       **picture)
    d = tuple(_five(p[2]) for p in ordered)
    return PtzLens(ZoomCurve(tuple(float(p[0]) for p in ordered),
                             tuple(float(p[1]) for p in ordered)),
                   tuple(float(p[1]) for p in ordered), d, **picture)


def _five(c: Sequence[float]) -> Distortion:
    k1, k2, p1, p2, k3 = (float(v) for v in c)
    return (k1, k2, p1, p2, k3)


def lens_of(pose: CameraPose) -> PtzLens:
    """The lens a calibrated pose carries, in the pose's picture: measured at two or more zoom
    steps, or (calibrated at one zoom) the data sheet's straight line."""
    return measured_lens([(p.zoom, p.focal_px, p.distortion) for p in pose.lens],
                         width_px=pose.width_px, height_px=pose.height_px,
                         principal_px=principal_of(pose))


def principal_of(pose: CameraPose) -> tuple[float, float] | None:
    """The principal point a pose carries (None: the picture's centre)."""
    if pose.principal_u_px is None or pose.principal_v_px is None:
        return None
    return pose.principal_u_px, pose.principal_v_px


def intrinsics_of(pose: CameraPose, zoom: float) -> Intrinsics:
    """The camera of a calibrated pose at ``zoom``: through its measured lens, or (one zoom)
    at the focal length the pose was fitted with."""
    if pose.lens:
        return lens_of(pose).intrinsics(zoom)
    return Intrinsics(pose.focal_px, pose.width_px, pose.height_px,
                      principal_px=principal_of(pose))
