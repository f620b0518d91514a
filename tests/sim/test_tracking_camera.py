"""The crane's tracking camera: the marker where the paper's thin-lens model puts it."""

from __future__ import annotations

import numpy as np

from common.camera import thin_lens_image_distance_mm
from services.sim.lab import Lab
from tests.sim.test_cameras import _bright_spots


def test_marker_renders_at_the_thin_lens_pixel_within_a_pixel(lab: Lab,
                                                              rng: np.random.Generator) -> None:
    cam = lab.tracking
    for t, offset in ((0.0, (150.0, -420.0)), (30.0, (-600.0, 200.0)), (55.0, (500, 400))):
        robot = lab.robot(t)
        crane_xy = (robot[0] + offset[0], robot[1] + offset[1])
        lab.crane.place(*crane_xy)  # disabled: it stays there
        u, v, radius = cam.pixel_of(robot, *crane_xy)
        assert 0 < u < cam.width_px and 0 < v < cam.height_px, "the test keeps it in view"
        image = lab.tracking_frame(t, rng)
        assert image.shape == (cam.height_px, cam.width_px) and image.dtype == np.uint8
        nearest = min(_bright_spots(image), key=lambda s: np.hypot(s[0] - u, s[1] - v))
        assert np.hypot(nearest[0] - u, nearest[1] - v) < 1.0
        assert 1.5 < radius < 10


def test_paper_equations_5_to_8_invert_the_rendering(lab: Lab) -> None:
    cam = lab.tracking
    robot = np.array([1234.0, -567.0, 210.0])
    crane_x, crane_y = 1000.0, -400.0
    u, v, _ = cam.pixel_of(robot, crane_x, crane_y)
    z = cam.height_mm - robot[2]
    b = thin_lens_image_distance_mm(cam.focal_mm, z)
    x_err = z / b * (u - cam.ref_u) * cam.pixel_mm
    y_err = -z / b * (v - cam.ref_v) * cam.pixel_mm  # image rows grow towards world −y
    np.testing.assert_allclose([x_err + crane_x, y_err + crane_y], robot[:2], atol=1e-6)


def test_stray_reflections_are_elongated(lab: Lab) -> None:
    assert lab.ground_glints, "the workspace has reflections"
    assert all(g.long_mm / g.short_mm > 2 for g in lab.ground_glints)
