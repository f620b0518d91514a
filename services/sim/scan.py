"""The crater as a terrestrial laser scanner delivers it (pure, randomness passed in): a point
cloud in world coordinates with its own density, a few millimetres of noise, and holes where no
scanner station could see the ground (behind rocks, inside mini craters' rims, walls facing
away) — what a lab has instead of our grid (paper §3.1: the look-up table comes from a laser
scan of the testbed).

Where the figures come from: a survey-grade scanner's points scatter 2.7–3.9 mm at 10–40 m;
at a room's scale a few millimetres (``noise_mm`` 2); the stations stand on tripods outside
the rim (1.2 m above the ground there), one on each side, as a lab scans a pit from its edge.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from common.heightmap import HeightMap

CHUNK = 100_000  # points checked for visibility at once (memory: CHUNK × steps lookups)
VISIBILITY_MM = 20.0


@dataclass(frozen=True)
class ScanOptions:
    spacing_mm: float = 3.0  # one point per spacing² of ground, on average
    noise_mm: float = 2.0  # each coordinate's scatter (1σ)
    stations: tuple[tuple[float, float, float], ...] = ((-3700.0, -600.0, 1200.0),
                                                      (3700.0, 600.0, 1200.0))
    """Scanner stations (x, y, height above the ground there), mm."""
    steps: int = 48  # samples along each line of sight
    clearance_mm: float = 3.0  # a line of sight this close to the ground is blocked


def scan(crater: HeightMap, rng: np.random.Generator, options: ScanOptions = ScanOptions()
         ) -> np.ndarray:
    """The point cloud (N, 3) in world mm: ground points that a station sees, with noise.
    What a station sees is judged on a grid of ``VISIBILITY_MM`` (finer than any point
    spacing it is used with makes no difference to the holes' shapes)."""
    x0, x1, y0, y1 = crater.extent_mm
    seen = _seen(crater, options)
    count = int((x1 - x0) * (y1 - y0) / options.spacing_mm ** 2)
    xy = np.column_stack([rng.uniform(x0, x1, count), rng.uniform(y0, y1, count)])
    col = np.clip(np.rint((xy[:, 0] - x0) / VISIBILITY_MM).astype(int), 0, seen.shape[1] - 1)
    row = np.clip(np.rint((xy[:, 1] - y0) / VISIBILITY_MM).astype(int), 0, seen.shape[0] - 1)
    xy = xy[seen[row, col]]
    points = np.column_stack([xy, crater.height_at(xy[:, 0], xy[:, 1])])
    return points + rng.normal(0.0, options.noise_mm, size=points.shape)


def _seen(crater: HeightMap, options: ScanOptions) -> np.ndarray:
    """(rows, cols) on a ``VISIBILITY_MM`` grid over the crater: seen by a station."""
    x0, x1, y0, y1 = crater.extent_mm
    gx = np.arange(x0, x1 + VISIBILITY_MM / 2, VISIBILITY_MM)
    gy = np.arange(y0, y1 + VISIBILITY_MM / 2, VISIBILITY_MM)
    x, y = (a.ravel() for a in np.meshgrid(gx, gy))
    ground = np.column_stack([x, y, crater.height_at(x, y)])
    stations = [np.array([sx, sy, float(crater.height_at(sx, sy)) + h])
                for sx, sy, h in options.stations]
    seen = np.zeros(len(ground), dtype=bool)
    for start in range(0, len(ground), CHUNK):
        chunk = ground[start:start + CHUNK]
        seen[start:start + CHUNK] = np.logical_or.reduce(
            [_visible(crater, chunk, station, options) for station in stations])
    return seen.reshape(len(gy), len(gx))


def _visible(crater: HeightMap, points: np.ndarray, station: np.ndarray,
             options: ScanOptions) -> np.ndarray:
    """Whether the line from each point to the station clears the ground."""
    fractions = np.linspace(0.0, 1.0, options.steps + 2)[1:-1]  # neither end
    along = points[:, None, :] + fractions[None, :, None] * (station - points)[:, None, :]
    ground = crater.height_at(along[..., 0], along[..., 1])
    return np.all(along[..., 2] > ground + options.clearance_mm, axis=1)
