"""The crater: slopes as in the STB, a file like a laser scan, interpolated heights."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from services.sim.world import CraterMap, CraterShape, generate_crater


def test_crater_walls_slope_between_30_and_45_degrees(crater: CraterMap) -> None:
    rows, cols = crater.heights_mm.shape
    xs = crater.origin_x_mm + np.arange(cols) * crater.resolution_mm
    ys = crater.origin_y_mm + np.arange(rows) * crater.resolution_mm
    r = np.hypot(*np.meshgrid(xs, ys))
    shape = CraterShape()
    wall = (r > shape.floor_radius_mm + 100) & (r < shape.rim_radius_mm - 100)
    slopes = crater.slope_deg()[wall]
    low, median, high = np.percentile(slopes, [10, 50, 90])
    assert low >= 29 and high <= 47 and 33 <= median <= 42
    floor = r < shape.floor_radius_mm - 100
    assert np.percentile(crater.slope_deg()[floor], 50) < 5, "a flat floor for the railway"


def test_rocks_and_mini_craters_make_the_ground_uneven(crater: CraterMap) -> None:
    plain = generate_crater(CraterShape(rocks=0, mini_craters=0), np.random.default_rng(1))
    difference = np.abs(crater.heights_mm - plain.heights_mm)
    assert difference.max() > 40  # at least one rock or crater of the generated sizes


def test_file_round_trip_and_interpolation(tmp_path: Path, crater: CraterMap) -> None:
    path = tmp_path / "scan.npz"
    crater.save(path)
    loaded = CraterMap.load(path)
    assert np.array_equal(loaded.heights_mm, crater.heights_mm)
    assert loaded.extent_mm == (-4000.0, 4000.0, -4000.0, 4000.0)
    # On grid points the interpolation returns the grid; between them it is bilinear.
    assert loaded.height_at(-4000.0 + 20 * 10, -4000.0 + 20 * 7) == pytest.approx(
        float(crater.heights_mm[7, 10]), abs=1e-3)
    h = crater.heights_mm
    mid = (h[7, 10] + h[7, 11] + h[8, 10] + h[8, 11]) / 4
    assert loaded.height_at(-4000.0 + 20 * 10.5, -4000.0 + 20 * 7.5) == pytest.approx(mid, 1e-4)


def test_same_seed_same_crater() -> None:
    a = generate_crater(CraterShape(), np.random.default_rng(5))
    b = generate_crater(CraterShape(), np.random.default_rng(5))
    assert np.array_equal(a.heights_mm, b.heights_mm)


@pytest.mark.parametrize("content", [b"not a zip", None])
def test_bad_height_map_file_is_a_clear_error(tmp_path: Path, content: bytes | None) -> None:
    path = tmp_path / "bad.npz"
    if content is None:
        np.savez(path, heights_mm=np.full((3, 3), np.nan), origin_mm=[0, 0], resolution_mm=10)
    else:
        path.write_bytes(content)
    with pytest.raises(ValueError, match="bad.npz"):
        CraterMap.load(path)
