"""A PTZ camera's zoom lens (pure): the VAPIX zoom step → focal length curve and the lens's
distortion as a function of focal length.

VAPIX reports a zoom *step* (1–9999), never a focal length, and a real zoom curve is far from
straight: it must be measured (``stb calib collect --zooms``). A curve through measured points
is interpolated by PCHIP (monotone, no overshoot between the points: a longer step never gives
a shorter focal length); outside the measured steps it holds the nearest end. Distortion
(OpenCV's k1, k2, p1, p2, k3 on normalised coordinates, ``common.lens``) is measured at some
focal lengths and interpolated linearly between them by focal length, holding the ends.

``STRAIGHT_LINE`` is what a camera calibrated at one zoom uses: the AXIS 215's 3.8–46 mm
(data sheet, the paper's Table 1) spread evenly over steps 1–9999, no distortion.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from common.camera import Intrinsics
from common.lens import NO_DISTORTION

AXIS_215_FOCAL_MM = (3.8, 46.0)
AXIS_215_ZOOM_STEPS = (1, 9999)
Distortion = tuple[float, float, float, float, float]


def _monotone_cubic(x: np.ndarray, y: np.ndarray) -> Callable[[np.ndarray | float], np.ndarray]:
    from scipy.interpolate import PchipInterpolator  # only when a curve has 3 points or more

    return PchipInterpolator(x, y, extrapolate=False)


@dataclass(frozen=True)
class ZoomCurve:
    """Focal length (mm) at zoom steps, both strictly increasing."""

    zooms: tuple[float, ...]
    focals_mm: tuple[float, ...]

    def __post_init__(self) -> None:
        z, f = np.asarray(self.zooms, float), np.asarray(self.focals_mm, float)
        if len(z) < 2 or len(z) != len(f):
            raise ValueError("a zoom curve needs two or more (zoom, focal) points")
        if np.any(np.diff(z) <= 0) or np.any(np.diff(f) <= 0):
            raise ValueError("a zoom curve's zoom steps and focal lengths must both increase: "
                             f"{list(zip(self.zooms, self.focals_mm, strict=True))}")
        if f[0] <= 0:
            raise ValueError(f"a focal length must be positive, not {f[0]}")

    @classmethod
    def of(cls, points: Sequence[Sequence[float]]) -> ZoomCurve:
        """From ``[[zoom, focal_mm], ...]`` (a lab file's table), sorted by zoom."""
        ordered = sorted((float(z), float(f)) for z, f in points)
        return cls(tuple(z for z, _ in ordered), tuple(f for _, f in ordered))

    @cached_property
    def _forward(self) -> Callable[[np.ndarray | float], np.ndarray]:
        """Zoom → focal length between the points: a line through two, PCHIP through more
        (scipy only then: a camera on the data sheet's line does without it)."""
        zooms, focals = np.asarray(self.zooms), np.asarray(self.focals_mm)
        if len(zooms) == 2:
            return lambda z: np.interp(z, zooms, focals)
        return _monotone_cubic(zooms, focals)

    @cached_property
    def _steps(self) -> tuple[np.ndarray, np.ndarray]:
        """Every whole zoom step of the curve and its focal length (increasing both)."""
        steps = np.arange(np.ceil(self.zooms[0]), np.floor(self.zooms[-1]) + 1)
        return steps, np.asarray(self._forward(steps), dtype=float)

    def focal_mm(self, zoom: float) -> float:
        return float(self._forward(min(max(float(zoom), self.zooms[0]), self.zooms[-1])))

    def zoom_for_focal(self, focal_mm: float) -> int:
        """The whole zoom step whose focal length is nearest to ``focal_mm`` (the curve's own
        inverse; clamped to its steps)."""
        steps, focal = self._steps
        i = int(np.clip(np.searchsorted(focal, focal_mm), 1, len(steps) - 1))
        nearer = i if abs(focal[i] - focal_mm) < abs(focal[i - 1] - focal_mm) else i - 1
        return int(steps[nearer])

    def points(self) -> list[tuple[float, float]]:
        return [(z, f) for z, f in zip(self.zooms, self.focals_mm, strict=True)]


STRAIGHT_LINE = ZoomCurve(tuple(float(z) for z in AXIS_215_ZOOM_STEPS), AXIS_215_FOCAL_MM)


@dataclass(frozen=True)
class PtzLens:
    """A zoom lens: its zoom curve and its distortion at some focal lengths."""

    curve: ZoomCurve = STRAIGHT_LINE
    distortion_focals_mm: tuple[float, ...] = ()
    distortions: tuple[Distortion, ...] = field(default=())

    def __post_init__(self) -> None:
        if len(self.distortion_focals_mm) != len(self.distortions):
            raise ValueError("one distortion per focal length it was measured at")
        if any(len(d) != 5 for d in self.distortions):
            raise ValueError("a distortion is five coefficients: k1, k2, p1, p2, k3")
        if np.any(np.diff(self.distortion_focals_mm) <= 0):
            raise ValueError("distortions must be listed by increasing focal length")

    def focal_mm(self, zoom: float) -> float:
        return self.curve.focal_mm(zoom)

    def zoom_for_focal(self, focal_mm: float) -> int:
        return self.curve.zoom_for_focal(focal_mm)

    def distortion(self, focal_mm: float) -> Distortion:
        """k1, k2, p1, p2, k3 at ``focal_mm``: linear in focal length between the measured
        ones, the nearest held beyond them."""
        if not self.distortions:
            return NO_DISTORTION
        table = np.asarray(self.distortions, dtype=float)
        d = [float(np.interp(focal_mm, self.distortion_focals_mm, table[:, i]))
             for i in range(5)]
        return (d[0], d[1], d[2], d[3], d[4])

    def intrinsics(self, zoom: float, width_px: int = 704, height_px: int = 576) -> Intrinsics:
        """The camera at ``zoom`` (the AXIS 215's chip, Table 1) in an image of this size."""
        focal = self.focal_mm(zoom)
        return Intrinsics(focal, width_px=width_px, height_px=height_px,
                          distortion=self.distortion(focal))

    @property
    def measured(self) -> bool:
        """False for the straight-line default (a camera calibrated at one zoom)."""
        return self.curve != STRAIGHT_LINE or bool(self.distortions)


def measured_lens(points: Sequence[tuple[int, float, Sequence[float]]]) -> PtzLens:
    """The lens from (zoom, focal_mm, distortion) measured at two or more zoom steps; fewer:
    the straight-line default (a camera calibrated at one zoom)."""
    ordered = sorted(points, key=lambda p: p[0])
    if len(ordered) < 2:
        return PtzLens()
    d = tuple(_five(p[2]) for p in ordered)
    return PtzLens(ZoomCurve(tuple(float(p[0]) for p in ordered),
                             tuple(float(p[1]) for p in ordered)),
                   tuple(float(p[1]) for p in ordered), d)


def _five(c: Sequence[float]) -> Distortion:
    k1, k2, p1, p2, k3 = (float(v) for v in c)
    return (k1, k2, p1, p2, k3)
