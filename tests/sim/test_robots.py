"""Scenario robots: the paper's locomotive, a swaying, sliding walker, a calibration marker."""

from __future__ import annotations

import numpy as np

from services.sim.robots import (
    Railway,
    Walk,
    calibration,
    locomotive,
    walker,
)
from services.sim.world import CraterMap


def _speeds(xyz: np.ndarray, hz: float = 100.0) -> np.ndarray:
    return np.linalg.norm(np.diff(xyz[:, :2], axis=0), axis=1) * hz


def test_locomotive_runs_five_rounds_at_29_cm_s_and_stops_at_its_start(
        crater: CraterMap) -> None:
    track = locomotive(crater)
    speeds = _speeds(track.xyz_mm)
    moving = speeds > 10
    assert abs(np.median(speeds[moving]) - 290.0) < 1.0
    travelled = speeds.sum() / 100.0
    assert abs(travelled - 5 * Railway().oval.length_mm) < 5.0
    np.testing.assert_allclose(track.xyz_mm[-1], track.xyz_mm[0], atol=0.5)
    assert speeds[-100:].max() < 1e-6, "standing still at the end"


def test_marker_follows_the_surface(crater: CraterMap, rng: np.random.Generator) -> None:
    for track, height in ((locomotive(crater), 80.0), (walker(crater, rng), 350.0)):
        ground = crater.height_at(track.xyz_mm[:, 0], track.xyz_mm[:, 1])
        above = track.xyz_mm[:, 2] - ground
        assert np.all(above >= height - 1e-6) and np.all(above <= height + 10.0)


def test_walker_is_slow_sways_and_sometimes_slides_downhill(crater: CraterMap) -> None:
    track = walker(crater, np.random.default_rng(2))
    speeds = _speeds(track.xyz_mm)
    assert 10 < np.median(speeds) < 100, "slow"
    # Its gait: the marker's path wiggles about the walking line.
    x = track.xyz_mm[:2000, 0]
    assert np.std(x - np.convolve(x, np.ones(250) / 250, mode="same")[:2000]) > 3.0
    sliding = walker(crater, np.random.default_rng(2), Walk(slide_per_s=0.05))
    slides = _speeds(sliding.xyz_mm) > 200
    assert slides.any(), "slides now and then"
    assert slides.mean() < 0.05, "but rarely"


def test_walker_is_deterministic_under_a_seed(crater: CraterMap) -> None:
    a = walker(crater, np.random.default_rng(9), Walk(duration_s=60))
    b = walker(crater, np.random.default_rng(9), Walk(duration_s=60))
    assert np.array_equal(a.xyz_mm, b.xyz_mm)


def test_calibration_marker_dwells_at_many_distinct_points(crater: CraterMap,
                                                           rng: np.random.Generator) -> None:
    track = calibration(crater, rng, points=40)
    still = _speeds(track.xyz_mm) < 1e-6
    assert still.mean() > 0.2, "held still for sharp snapshots"
    spots = np.unique(np.round(track.xyz_mm[1:][still] / 50), axis=0)
    assert len(spots) >= 35
    assert np.ptp(track.xyz_mm[:, 2]) > 800, "spread in height too (not a plane)"
