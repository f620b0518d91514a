"""The crater: a height map on a millimetre grid, made from a seed, stored like a laser scan.

World frame: x, y horizontal, z up, millimetres, origin at the centre of the crater floor (the
mocap's frame). The map is a grid ``heights_mm[row, col]`` with row ↔ y and col ↔ x:
``x = origin_x_mm + col * resolution_mm``, ``y = origin_y_mm + row * resolution_mm``.

File format (``.npz``, numpy's zip of arrays), what a laser scan of the crater is turned into:
``heights_mm`` (float32, rows × cols), ``origin_mm`` ([x, y] of element [0, 0]) and
``resolution_mm`` (grid spacing). The map itself, its file and its interpolation are
``common.heightmap.HeightMap`` (the gantry's height look-up table reads the same file).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from common.heightmap import HeightMap as CraterMap


@dataclass(frozen=True)
class CraterShape:
    """Parameters of the generated crater (mm, degrees)."""

    half_size_mm: float = 4000.0
    resolution_mm: float = 20.0
    floor_radius_mm: float = 1500.0
    rim_radius_mm: float = 3000.0
    slope_min_deg: float = 30.0
    slope_max_deg: float = 45.0
    rocks: int = 25
    mini_craters: int = 6
    keep_clear: tuple[tuple[float, float, float], ...] = ()
    """Discs (x, y, radius) where no rock or mini crater is placed (the railway)."""


def generate_crater(shape: CraterShape, rng: np.random.Generator) -> CraterMap:
    """A bowl with a flat floor, walls of 30°–45° slope, rocks and mini craters."""
    n = int(round(2 * shape.half_size_mm / shape.resolution_mm)) + 1
    axis = np.linspace(-shape.half_size_mm, shape.half_size_mm, n)
    x, y = np.meshgrid(axis, axis)
    heights = _bowl(x, y, shape, rng)
    for _ in range(shape.rocks):
        cx, cy = _free_spot(shape, rng)
        radius, height = rng.uniform(80, 250), rng.uniform(40, 150)
        heights += height * np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / (2 * (radius / 2) ** 2))
    for _ in range(shape.mini_craters):
        cx, cy = _free_spot(shape, rng)
        radius, depth = rng.uniform(150, 350), rng.uniform(40, 100)
        d = np.hypot(x - cx, y - cy) / radius
        bowl = np.where(d < 1, -depth * (1 - d**2), 0.0)
        rim = 0.3 * depth * np.exp(-(((d - 1) / 0.15) ** 2))
        heights += bowl + rim
    return CraterMap(heights.astype(np.float32), -shape.half_size_mm, -shape.half_size_mm,
                     shape.resolution_mm)


def _bowl(x: np.ndarray, y: np.ndarray, shape: CraterShape,
          rng: np.random.Generator) -> np.ndarray:
    r = np.hypot(x, y)
    azimuth = np.arctan2(y, x)
    mid = (shape.slope_min_deg + shape.slope_max_deg) / 2
    half = (shape.slope_max_deg - shape.slope_min_deg) / 2
    phase = rng.uniform(0, 2 * np.pi)
    slope = np.radians(mid + half * np.sin(2 * azimuth + phase))
    wall = np.clip(r, shape.floor_radius_mm, shape.rim_radius_mm) - shape.floor_radius_mm
    return wall * np.tan(slope)


def _free_spot(shape: CraterShape, rng: np.random.Generator) -> tuple[float, float]:
    for _ in range(1000):
        cx, cy = rng.uniform(-shape.rim_radius_mm, shape.rim_radius_mm, size=2)
        if all(np.hypot(cx - kx, cy - ky) > kr for kx, ky, kr in shape.keep_clear):
            return float(cx), float(cy)
    raise ValueError("no room for crater features outside the keep-clear discs")
