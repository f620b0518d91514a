"""Scans the crater tests and the fault campaign import: written to files the way scanners
write them."""

from __future__ import annotations

from pathlib import Path

import laspy
import numpy as np

from common.heightmap import HeightMap


def write_las(path: Path, points: np.ndarray, scale: float = 0.001) -> None:
    """``points`` (N × 3) as a LAS 1.2 file quantised to ``scale``."""
    header = laspy.LasHeader(point_format=3, version="1.2")
    header.scales = np.array([scale] * 3)
    header.offsets = np.floor(points.min(axis=0))
    las = laspy.LasData(header)
    las.x, las.y, las.z = points[:, 0], points[:, 1], points[:, 2]
    las.write(str(path))


def sparse_terrain(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The ground under ``sparse_quantised_scan`` (mm)."""
    return 300 + 0.25 * x - 0.1 * y + 40 * np.sin(x / 400)


def sparse_quantised_scan(path: Path, seed: int = 7) -> None:
    """Scan lines 37 mm apart, points 4 mm apart along them, over ±1 m of
    ``sparse_terrain``, written to LAS at 1 mm: most 15 mm cells hold the points of one line
    only, on a line — no plane through them."""
    rng = np.random.default_rng(seed)
    lines = []
    for y in np.arange(-1000.0, 1000.0, 37.0):
        x = np.arange(-1000.0, 1000.0, 4.0) + rng.uniform(-1, 1)
        lines.append(np.column_stack([x, y + 0.002 * x, sparse_terrain(x, y + 0.002 * x)]))
    write_las(path, np.vstack(lines), scale=1.0)  # in mm, 1 mm steps


def sparse_cells_off(heights: HeightMap) -> tuple[np.ndarray, np.ndarray]:
    """How far each cell of a map of ``sparse_quantised_scan`` is off its ground, and which
    cells lie inside the scanned square (a margin from its edge)."""
    rows, cols = np.indices(heights.heights_mm.shape)
    x = np.asarray(heights.origin_x_mm + cols * heights.resolution_mm)
    y = np.asarray(heights.origin_y_mm + rows * heights.resolution_mm)
    return np.abs(heights.heights_mm - sparse_terrain(x, y)), (np.abs(x) < 950) & (np.abs(y) < 950)


BROKEN_XYZ = "0 0 0\n1000 0 0\n0 1000 0\n1000 1000 5\nnan 5 5\n1e300 0 0\n"
"""A scan with a NaN point and one 10³⁰⁰ mm away (each once ended in a traceback)."""
