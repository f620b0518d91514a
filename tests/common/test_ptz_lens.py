"""The PTZ zoom lens (pure): the zoom → focal curve through points, its inverse, distortion by
focal length, and projection through the lens against OpenCV's own ``projectPoints``."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from common import messages as m
from common.camera import (
    Intrinsics,
    Pose,
    picture_pixel_aspect,
    project,
    project_camera,
    undistort_pixels,
)
from common.ptz_lens import (
    STRAIGHT_LINE,
    PtzLens,
    ZoomCurve,
    axis_215,
    axis_215_px,
    intrinsics_of,
    lens_of,
    measured_lens,
    straight_line,
)


def test_the_default_is_the_data_sheets_straight_line_in_pixels() -> None:
    per_mm = 704 / 3.6  # the AXIS 215's picture over its chip (Table 1)
    assert STRAIGHT_LINE.focal(1) == pytest.approx(3.8 * per_mm)
    assert STRAIGHT_LINE.focal(9999) == pytest.approx(46.0 * per_mm)
    assert STRAIGHT_LINE.focal(0) == STRAIGHT_LINE.focal(1)
    assert STRAIGHT_LINE.focal(20000) == STRAIGHT_LINE.focal(9999)
    assert STRAIGHT_LINE.focal(5000) == pytest.approx((3.8 + 42.2 * 4999 / 9998) * per_mm)
    for zoom in (1, 2500, 5000, 9999):
        assert STRAIGHT_LINE.zoom_for_focal(STRAIGHT_LINE.focal(zoom)) == zoom
    assert not PtzLens().measured
    wide = PtzLens().intrinsics(1)  # the AXIS 215's non-square PAL pixels: 3.6 × 2.7 mm chip
    assert wide.fy_px == pytest.approx(3.8 / (3.6 / 704))
    assert wide.fz_px == pytest.approx(3.8 / (2.7 / 576))
    assert wide.fy_px == pytest.approx(axis_215(3.8).fy_px)
    assert wide.fz_px == pytest.approx(axis_215(3.8).fz_px)


def test_a_picture_of_another_size_scales_the_lens_and_keeps_its_view() -> None:
    """Half the size of the same picture: half the focal length, the same angles; a 16:9
    picture has square pixels; a lens of a 1920 × 1080 camera keeps its principal point."""
    lens = PtzLens(principal_px=(360.0, 280.0))
    full, half = lens.intrinsics(5000), lens.intrinsics(5000, 352, 288)
    assert half.fy_px == pytest.approx(full.fy_px / 2) and half.fz_px == pytest.approx(
        full.fz_px / 2)
    assert (half.cy_px, half.cz_px) == pytest.approx((180.0, 140.0))
    assert Intrinsics(1500.0, 1920, 1080).fz_px == 1500.0
    hd = PtzLens(straight_line(1920), width_px=1920, height_px=1080,
                 principal_px=(975.5, 531.0))
    assert not hd.measured
    intr = hd.intrinsics(1)
    assert (intr.width_px, intr.cy_px, intr.cz_px) == (1920, 975.5, 531.0)
    assert intr.fz_px == intr.fy_px  # square pixels
    for zoom in (1, 3000, 9999):
        assert hd.zoom_for_view(hd.half_view_deg(zoom)) == zoom
    assert math.degrees(math.atan(540 / intr.fz_px)) == pytest.approx(hd.half_view_deg(1))


def test_a_chip_gives_the_pixels_their_aspect() -> None:
    four_three = Intrinsics.from_chip(3.8, (3.6, 2.7), 704, 576)
    assert four_three.fz_px / four_three.fy_px == pytest.approx(12 / 11)
    assert four_three.fz_px / four_three.fy_px == pytest.approx(picture_pixel_aspect(704, 576))
    assert picture_pixel_aspect(1920, 1080) == 1.0 and picture_pixel_aspect(704, 480) == \
        pytest.approx(10 / 11)
    sixteen_nine = Intrinsics.from_chip(4.7, (5.12, 2.88), 1920, 1080)
    assert sixteen_nine.fz_px == pytest.approx(sixteen_nine.fy_px)


def test_a_pose_written_in_millimetres_is_read_in_pixels() -> None:
    """A pose stored (or recorded) before focal lengths were pixels: the AXIS 215's mm."""
    old = {"measured_s": 1.0, "camera": "ptz1", "x_mm": 0.0, "y_mm": 0.0, "z_mm": 0.0,
           "rx_deg": 0.0, "ry_deg": 0.0, "rz_deg": 0.0, "focal_mm": 3.8, "mean_error_px": 1.0,
           "passpoints": 30, "lens": [
               {"zoom": 1, "focal_mm": 3.8, "distortion": [0, 0, 0, 0, 0], "passpoints": 9,
                "mean_error_px": 0.4},
               {"zoom": 9999, "focal_mm": 46.0, "distortion": [0, 0, 0, 0, 0],
                "passpoints": 9, "mean_error_px": 0.4}]}
    pose = m.CameraPose.model_validate(old, strict=False)
    assert pose.focal_px == pytest.approx(axis_215_px(3.8))
    assert [at.focal_px for at in pose.lens] == pytest.approx([axis_215_px(3.8),
                                                                 axis_215_px(46.0)])
    assert (pose.width_px, pose.height_px) == (704, 576)
    assert lens_of(pose).intrinsics(9999).fy_px == pytest.approx(axis_215(46.0).fy_px)
    assert intrinsics_of(pose.model_copy(update={"lens": []}), 5000).fy_px == \
        pytest.approx(axis_215(3.8).fy_px)


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
    for z, f in zip(curve.zooms, curve.focals, strict=True):
        assert curve.focal(z) == pytest.approx(f)
    steps = np.arange(1, 10000, 7)
    focal = np.array([curve.focal(float(z)) for z in steps])
    assert np.all(np.diff(focal) > 0)  # monotone: no overshoot between the points
    for z in (1, 777, 4321, 8888, 9999):
        assert curve.zoom_for_focal(curve.focal(z)) == z
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
    lens = PtzLens(STRAIGHT_LINE, (700.0, 9000.0), (wide, long))
    assert lens.distortion(700.0) == pytest.approx(wide)
    assert lens.distortion(400.0) == pytest.approx(wide)  # held beyond the ends
    assert lens.distortion(4850.0)[0] == pytest.approx(-0.15)
    assert lens.measured
    built = measured_lens([(9999, 9000.0, long), (1, 700.0, wide)])
    assert built.distortion(700.0) == pytest.approx(wide) and built.focal_px(9999) == 9000.0
    assert measured_lens([(1, 700.0, wide)]) == PtzLens()  # one zoom: no curve


def test_projection_through_the_lens_is_opencvs() -> None:
    """Camera frame x forward, y right, z down ↔ OpenCV's z forward, x right, y down."""
    rng = np.random.default_rng(3)
    intr = axis_215(4.2, distortion=(-0.28, 0.09, 0.0012, -0.0008, -0.01))
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
