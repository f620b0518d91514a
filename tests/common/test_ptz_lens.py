"""The PTZ zoom lens (pure): the zoom → focal curve through points, its inverse, distortion by
focal length, and projection through the lens against OpenCV's own ``projectPoints``."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from common.camera import Intrinsics, Pose, project, project_camera, undistort_pixels
from common.ptz_lens import STRAIGHT_LINE, PtzLens, ZoomCurve, measured_lens


def test_the_default_is_the_data_sheets_straight_line() -> None:
    assert STRAIGHT_LINE.focal_mm(1) == 3.8 and STRAIGHT_LINE.focal_mm(9999) == 46.0
    assert STRAIGHT_LINE.focal_mm(0) == 3.8 and STRAIGHT_LINE.focal_mm(20000) == 46.0
    assert STRAIGHT_LINE.focal_mm(5000) == pytest.approx(3.8 + 42.2 * 4999 / 9998)
    for zoom in (1, 2500, 5000, 9999):
        assert STRAIGHT_LINE.zoom_for_focal(STRAIGHT_LINE.focal_mm(zoom)) == zoom
    assert not PtzLens().measured


def _bent_curve(rng: np.random.Generator, points: int) -> ZoomCurve:
    """A zoom curve slow over most steps and steep near the end, at random steps."""
    inner = np.sort(rng.choice(np.arange(2, 9999), size=points - 2, replace=False))
    zooms = np.concatenate([[1], inner, [9999]]).astype(float)
    power = rng.uniform(1.5, 3.0)
    focal = 3.8 * (46.0 / 3.8) ** ((zooms / 9999) ** power)
    return ZoomCurve(tuple(zooms), tuple(focal))


@pytest.mark.parametrize("seed", range(5))
def test_a_curve_passes_its_points_rises_everywhere_and_inverts_to_the_nearest_step(
        seed: int) -> None:
    curve = _bent_curve(np.random.default_rng(seed), 6)
    for z, f in zip(curve.zooms, curve.focals_mm, strict=True):
        assert curve.focal_mm(z) == pytest.approx(f)
    steps = np.arange(1, 10000, 7)
    focal = np.array([curve.focal_mm(float(z)) for z in steps])
    assert np.all(np.diff(focal) > 0)  # monotone: no overshoot between the points
    for z in (1, 777, 4321, 8888, 9999):
        assert curve.zoom_for_focal(curve.focal_mm(z)) == z
    assert curve.zoom_for_focal(1.0) == 1 and curve.zoom_for_focal(100.0) == 9999


def test_a_table_that_is_no_curve_is_refused_saying_why() -> None:
    with pytest.raises(ValueError, match="two or more"):
        ZoomCurve.of([(1, 3.8)])
    with pytest.raises(ValueError, match="must both increase"):
        ZoomCurve.of([(1, 3.8), (5000, 3.0), (9999, 46.0)])
    with pytest.raises(ValueError, match="positive"):
        ZoomCurve.of([(1, -1.0), (9999, 46.0)])


def test_distortion_is_linear_in_focal_length_between_the_measured_ones() -> None:
    wide, long = (-0.3, 0.1, 0.001, -0.002, 0.0), (0.0, 0.0, 0.0, 0.0, 0.0)
    lens = PtzLens(STRAIGHT_LINE, (3.8, 46.0), (wide, long))
    assert lens.distortion(3.8) == pytest.approx(wide)
    assert lens.distortion(2.0) == pytest.approx(wide)  # held beyond the ends
    assert lens.distortion(24.9)[0] == pytest.approx(-0.15)
    assert lens.measured
    built = measured_lens([(9999, 46.0, long), (1, 3.8, wide)])
    assert built.distortion(3.8) == pytest.approx(wide) and built.focal_mm(9999) == 46.0
    assert measured_lens([(1, 3.8, wide)]) == PtzLens()  # one zoom: no curve


def test_projection_through_the_lens_is_opencvs() -> None:
    """Camera frame x forward, y right, z down ↔ OpenCV's z forward, x right, y down."""
    rng = np.random.default_rng(3)
    intr = Intrinsics(4.2, distortion=(-0.28, 0.09, 0.0012, -0.0008, -0.01))
    points = np.column_stack([rng.uniform(2000, 6000, 50), rng.uniform(-2000, 2000, 50),
                              rng.uniform(-1500, 1500, 50)])
    k = np.array([[intr.fy_px, 0, intr.cy_px], [0, intr.fz_px, intr.cz_px], [0, 0, 1]])
    opencv, _ = cv2.projectPoints(points[:, [1, 2, 0]], np.zeros(3), np.zeros(3), k,
                                  np.array(intr.distortion))
    np.testing.assert_allclose(project_camera(points, intr), opencv.reshape(-1, 2), atol=1e-9)
    straight = project_camera(points, intr.pinhole())
    np.testing.assert_allclose(undistort_pixels(project_camera(points, intr), intr), straight,
                               atol=1e-6)
    behind = project(np.array([[0.0, 0.0, 0.0]]), Pose(1000, 0, 0, 0, 0, 0), intr)
    assert np.all(np.isnan(behind))
