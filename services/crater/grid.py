"""A laser scan's points binned into the height map the gantry reads (pure): paper §3.1's
look-up table from a scan of the testbed.

Each cell's height is a plane fitted to the points in it, taken at the cell's centre (a mean
would lean downhill on a 45° wall wherever the points in a cell are not centred); a cell with
fewer than ``MIN_POINTS`` points, or whose plane would swing at its centre (its points all on
one side, as at a hole's edge), is a hole. Holes are filled by linear interpolation over the
cells around them (the nearest cell outside their hull) and reported — how many, and the
largest connected one — since an interpolated surface is a guess where the scanner saw nothing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.interpolate import griddata

from common.heightmap import HeightMap

MIN_POINTS = 3
PLANE_VARIANCE = 3.0
LINE_SPREAD = 0.1
"""A cell's points spread less than this share of the cell across their main direction lie on
a line (a plane through them is not defined)."""
MAX_COORDINATE_MM = 1e8  # 100 km: farther is no crater's point
MAX_CELLS = 50_000_000  # 200 MB of float32: a 100 × 100 m hall at 15 mm is 44 M


@dataclass(frozen=True)
class Gridded:
    heights: HeightMap
    filled: np.ndarray  # bool (rows, cols): cells interpolated (no scan points of their own)
    points: int
    cells: int
    largest_hole_cells: int
    largest_hole_at_mm: tuple[float, float] | None  # its centre

    @property
    def filled_cells(self) -> int:
        return int(self.filled.sum())

    def report(self) -> str:
        cell = self.heights.resolution_mm
        x0, x1, y0, y1 = self.heights.extent_mm
        lines = [f"{self.points} points → {self.heights.heights_mm.shape[1]} × "
                 f"{self.heights.heights_mm.shape[0]} cells of {cell:g} mm, x {x0:.0f}…{x1:.0f}"
                 f" mm, y {y0:.0f}…{y1:.0f} mm; heights {self.heights.heights_mm.min():.0f}…"
                 f"{self.heights.heights_mm.max():.0f} mm",
                 f"holes filled by interpolation: {self.filled_cells} cells "
                 f"({100 * self.filled_cells / self.cells:.1f} %)"]
        if self.largest_hole_at_mm is not None:
            x, y = self.largest_hole_at_mm
            lines.append(f"largest hole: {self.largest_hole_cells} cells "
                         f"({self.largest_hole_cells * cell * cell / 1e6:.3f} m²) around "
                         f"({x:.0f}, {y:.0f}) mm")
        return "\n".join(lines)


def grid_points(points: np.ndarray, cell_mm: float) -> Gridded:
    """The height map of ``points`` (N, 3, mm) at ``cell_mm``; holes filled and counted."""
    if cell_mm <= 0:
        raise ValueError("the cell size must be positive")
    far = float(np.abs(points).max())
    if far > MAX_COORDINATE_MM:
        raise ValueError(f"a point lies {far:.3g} mm from the scan's origin (more than "
                         f"{MAX_COORDINATE_MM / 1e6:g} km): a broken point, or the wrong "
                         "units (--units)?")
    x0 = np.floor(points[:, 0].min() / cell_mm) * cell_mm
    y0 = np.floor(points[:, 1].min() / cell_mm) * cell_mm
    span_cols = float(np.rint((points[:, 0].max() - x0) / cell_mm)) + 1
    span_rows = float(np.rint((points[:, 1].max() - y0) / cell_mm)) + 1
    if span_cols * span_rows > MAX_CELLS:
        raise ValueError(f"the points span {span_cols * cell_mm / 1000:.0f} × "
                         f"{span_rows * cell_mm / 1000:.0f} m: {span_cols * span_rows:.3g} cells "
                         f"of {cell_mm:g} mm, more than {MAX_CELLS:,}: a larger cell?")
    cols, rows = int(span_cols), int(span_rows)
    if rows < 2 or cols < 2:
        raise ValueError(f"the points cover less than 2 × 2 cells of {cell_mm:g} mm")
    heights, counts = _fit_planes(points, x0, y0, cell_mm, rows, cols)
    hole = counts < MIN_POINTS
    if hole.all():
        raise ValueError(f"no cell of {cell_mm:g} mm has {MIN_POINTS} points: a larger cell?")
    if hole.any():
        heights = _fill(heights, hole)
    labels, found = ndimage.label(hole)
    largest, at = 0, None
    if found:
        sizes = np.bincount(labels.ravel())[1:]
        biggest = int(np.argmax(sizes)) + 1
        largest = int(sizes[biggest - 1])
        r, c = np.argwhere(labels == biggest).mean(axis=0)
        at = (float(x0 + c * cell_mm), float(y0 + r * cell_mm))
    return Gridded(HeightMap(heights.astype(np.float32), x0, y0, cell_mm), hole, len(points),
                   rows * cols, largest, at)


def _fit_planes(points: np.ndarray, x0: float, y0: float, cell: float, rows: int, cols: int
                ) -> tuple[np.ndarray, np.ndarray]:
    """Per cell: z = a + b·dx + c·dy over its points (dx, dy from the cell's centre, the
    grid's node), least squares from summed moments; ``a`` is the cell's height."""
    col = np.clip(np.rint((points[:, 0] - x0) / cell).astype(np.int64), 0, cols - 1)
    row = np.clip(np.rint((points[:, 1] - y0) / cell).astype(np.int64), 0, rows - 1)
    index = row * cols + col
    dx = points[:, 0] - (x0 + col * cell)
    dy = points[:, 1] - (y0 + row * cell)
    z = points[:, 2]
    size = rows * cols

    def total(weights: np.ndarray | None = None) -> np.ndarray:
        return np.bincount(index, weights, minlength=size)

    n = total()
    sx, sy, sz = total(dx), total(dy), total(z)
    sxx, sxy, syy = total(dx * dx), total(dx * dy), total(dy * dy)
    sxz, syz = total(dx * z), total(dy * z)
    matrix = np.stack([np.stack([n, sx, sy], -1), np.stack([sx, sxx, sxy], -1),
                       np.stack([sy, sxy, syy], -1)], -2)
    rhs = np.stack([sz, sxz, syz], -1)
    heights = np.full(size, np.nan)
    # A cell's plane counts only where it is well supported at the centre: its centre value's
    # variance (noise² · (M⁻¹)₀₀) at most PLANE_VARIANCE times that of the points' mean
    # (noise² / n). Else (few points, all on one side, as at a hole's edge) the cell is a
    # hole: neither a swinging plane nor a mean that leans with the slope.
    candidates = np.flatnonzero(n >= MIN_POINTS)
    line = _along_a_line(n, sx, sy, sxx, sxy, syy, sz, sxz, syz, candidates, cell)
    planar = candidates[~line.on_line]
    inverse = np.linalg.pinv(matrix[planar])
    steady = inverse[:, 0, 0] * n[planar] <= PLANE_VARIANCE
    pick = planar[steady]
    heights[pick] = (inverse[steady] @ rhs[pick][..., None])[:, 0, 0]
    on_line = candidates[line.on_line]
    heights[on_line[line.steady]] = line.heights[line.steady]
    n = np.where(np.isfinite(heights), n, 0)
    return heights.reshape(rows, cols), n.reshape(rows, cols)


@dataclass(frozen=True)
class _Line:
    on_line: np.ndarray  # per candidate: its points lie on a line (a plane is not defined)
    heights: np.ndarray  # per cell on a line: z along the line, at the centre's foot
    steady: np.ndarray  # per cell on a line: that value is not a long extrapolation


def _along_a_line(n: np.ndarray, sx: np.ndarray, sy: np.ndarray, sxx: np.ndarray,
                  sxy: np.ndarray, syy: np.ndarray, sz: np.ndarray, sxz: np.ndarray,
                  syz: np.ndarray, candidates: np.ndarray, cell: float) -> _Line:
    """Cells whose points lie on a line — one scan line through a sparse scan, its
    coordinates quantised to 1 mm — have no plane: its least squares are singular, and the
    smallest-norm answer pulled the height toward 0 (301 mm off once). There the height is
    the line's own fit, z = a + b·t along it, at the foot of the cell's centre; the slope
    across the line is taken as none."""
    k = candidates
    count = n[k]
    mx, my, mz = sx[k] / count, sy[k] / count, sz[k] / count
    cxx, cyy, cxy = sxx[k] / count - mx * mx, syy[k] / count - my * my, sxy[k] / count - mx * my
    half_sum, half_diff = (cxx + cyy) / 2, np.hypot((cxx - cyy) / 2, cxy)
    minor, major = half_sum - half_diff, half_sum + half_diff
    on_line = minor < (LINE_SPREAD * cell) ** 2
    angle = 0.5 * np.arctan2(2 * cxy, cxx - cyy)  # the major axis
    ux, uy = np.cos(angle), np.sin(angle)
    czx, czy = sxz[k] / count - mx * mz, syz[k] / count - my * mz
    spread = np.maximum(major, 1e-12)
    slope = np.where(major > 1e-6, (czx * ux + czy * uy) / spread, 0.0)
    mean_t = mx * ux + my * uy  # the points' middle along the line; the centre's foot is 0
    heights = mz - slope * mean_t
    steady = np.where(major > 1e-6, 1 + mean_t ** 2 / spread <= PLANE_VARIANCE,
                      np.hypot(mx, my) <= cell / 2)
    return _Line(on_line, heights[on_line], steady[on_line])


def _fill(heights: np.ndarray, hole: np.ndarray) -> np.ndarray:
    """Holes by linear interpolation from the cells around them; beyond their hull, the
    nearest cell."""
    known = ~hole
    ring = known & ndimage.binary_dilation(hole, iterations=3)  # only the holes' neighbours
    source = np.argwhere(ring)
    target = np.argwhere(hole)
    values = heights[ring]
    out = heights.copy()
    filled = griddata(source, values, target, method="linear")
    missing = ~np.isfinite(filled)
    if missing.any():
        filled[missing] = griddata(np.argwhere(known), heights[known], target[missing],
                                   method="nearest")
    out[hole] = filled
    return out
