"""A height map of the crater floor: the laser scan the gantry's look-up table comes from
(paper §3.1), and the sim's ground.

World frame: x, y horizontal, z up, millimetres, origin at the centre of the crater floor (the
mocap's frame). The map is a grid ``heights_mm[row, col]`` with row ↔ y and col ↔ x:
``x = origin_x_mm + col * resolution_mm``, ``y = origin_y_mm + row * resolution_mm``.

File format (``.npz``, numpy's zip of arrays): ``heights_mm`` (float32, rows × cols),
``origin_mm`` ([x, y] of element [0, 0]) and ``resolution_mm`` (grid spacing).
"""

from __future__ import annotations

import io
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from common.files import write_atomically


@dataclass(frozen=True)
class HeightMap:
    heights_mm: np.ndarray
    origin_x_mm: float
    origin_y_mm: float
    resolution_mm: float

    @property
    def extent_mm(self) -> tuple[float, float, float, float]:
        """(x_min, x_max, y_min, y_max) covered by the grid."""
        rows, cols = self.heights_mm.shape
        return (self.origin_x_mm, self.origin_x_mm + (cols - 1) * self.resolution_mm,
                self.origin_y_mm, self.origin_y_mm + (rows - 1) * self.resolution_mm)

    def height_at(self, x_mm: np.ndarray | float, y_mm: np.ndarray | float) -> np.ndarray:
        """Surface height (mm) by bilinear interpolation; outside the grid: the nearest edge."""
        rows, cols = self.heights_mm.shape
        if isinstance(x_mm, float | int) and isinstance(y_mm, float | int):
            return np.asarray(self._height_at_point(float(x_mm), float(y_mm), rows, cols))
        fx = np.clip((np.asarray(x_mm, float) - self.origin_x_mm) / self.resolution_mm,
                     0, cols - 1.000001)
        fy = np.clip((np.asarray(y_mm, float) - self.origin_y_mm) / self.resolution_mm,
                     0, rows - 1.000001)
        c0, r0 = fx.astype(int), fy.astype(int)
        dx, dy = fx - c0, fy - r0
        h = self.heights_mm
        return ((h[r0, c0] * (1 - dx) + h[r0, c0 + 1] * dx) * (1 - dy)
                + (h[r0 + 1, c0] * (1 - dx) + h[r0 + 1, c0 + 1] * dx) * dy)

    def _height_at_point(self, x: float, y: float, rows: int, cols: int) -> float:
        """``height_at`` of one point in plain floats (the gantry's eq. 5–8, per frame)."""
        fx = min(max((x - self.origin_x_mm) / self.resolution_mm, 0.0), cols - 1.000001)
        fy = min(max((y - self.origin_y_mm) / self.resolution_mm, 0.0), rows - 1.000001)
        c0, r0 = int(fx), int(fy)
        dx, dy = fx - c0, fy - r0
        h = self.heights_mm
        return float((h[r0, c0] * (1 - dx) + h[r0, c0 + 1] * dx) * (1 - dy)
                     + (h[r0 + 1, c0] * (1 - dx) + h[r0 + 1, c0 + 1] * dx) * dy)

    def slope_deg(self) -> np.ndarray:
        """Steepest slope at every grid point, degrees."""
        gy, gx = np.gradient(self.heights_mm.astype(float), self.resolution_mm)
        return np.degrees(np.arctan(np.hypot(gx, gy)))

    def gradient(self, x_mm: float, y_mm: float) -> np.ndarray:
        """(dz/dx, dz/dy) at a point, by central differences over one grid step."""
        step = self.resolution_mm
        gx = (self.height_at(x_mm + step, y_mm) - self.height_at(x_mm - step, y_mm)) / (2 * step)
        gy = (self.height_at(x_mm, y_mm + step) - self.height_at(x_mm, y_mm - step)) / (2 * step)
        return np.array([float(gx), float(gy)])

    def slope_at(self, x_mm: float, y_mm: float) -> float:
        """Steepest slope at a point, degrees."""
        return float(np.degrees(np.arctan(np.linalg.norm(self.gradient(x_mm, y_mm)))))

    def downhill(self, x_mm: float, y_mm: float) -> np.ndarray:
        """Unit vector (x, y) pointing downhill at a point (zero on flat ground)."""
        g = -self.gradient(x_mm, y_mm)
        n = np.linalg.norm(g)
        return g / n if n > 1e-9 else np.zeros(2)

    def save(self, path: Path, **extra: np.ndarray) -> None:
        """Write the map whole or not at all: other processes read it as it is written.
        ``extra``: more arrays beside it (an imported scan's ``filled`` cells)."""
        buffer = io.BytesIO()
        arrays: dict[str, Any] = {"heights_mm": self.heights_mm.astype(np.float32),
                  "origin_mm": np.array([self.origin_x_mm, self.origin_y_mm]),
                  "resolution_mm": np.array(self.resolution_mm), **extra}
        np.savez_compressed(buffer, **arrays)
        write_atomically(path, buffer.getvalue())

    @classmethod
    def load(cls, path: Path) -> HeightMap:
        """Read a height map file; ValueError naming what is wrong with it."""
        try:
            with np.load(path) as data:
                heights = np.asarray(data["heights_mm"], dtype=np.float32)
                origin = np.asarray(data["origin_mm"], dtype=float)
                resolution = float(data["resolution_mm"])
        except (OSError, KeyError, ValueError, EOFError, zipfile.BadZipFile) as err:
            raise ValueError(f"{path} is not a crater height map: {err}") from err
        if heights.ndim != 2 or min(heights.shape) < 2 or not np.all(np.isfinite(heights)):
            raise ValueError(f"{path}: heights_mm must be a finite 2-D grid of at least 2 × 2")
        if origin.shape != (2,) or not resolution > 0:
            raise ValueError(f"{path}: origin_mm must be [x, y] and resolution_mm > 0")
        return cls(heights, float(origin[0]), float(origin[1]), resolution)
