"""The crane's tracking camera and the crane's frame as the sim plays them: the marker where the
sim's own lens and mount put it (OpenCV's projection), the crane counting in its own frame, the
motion capture's crane marker and the truth in the world's."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from common.camera import thin_lens_image_distance_mm
from services.sim.lab import Lab
from services.sim.settings import CraneSettings, TrackingCameraSettings
from services.sim.world import CraterMap
from tests.ports import free_port
from tests.sim.test_cameras import _bright_spots
from tests.simlab import sim_settings

ASKEW = {"crane": CraneSettings(port=free_port(), origin_mm=(-3600.0, 3300.0), yaw_deg=1.4,
                                flip_y=True, x_min_mm=0.0, x_max_mm=7200.0, y_min_mm=0.0,
                                y_max_mm=6600.0),
         "tracking_camera": TrackingCameraSettings(
             principal_px=(331.0, 228.5), distortion=(-0.29, 0.11, 0.001, -0.0002, 0.04),
             yaw_deg=-2.5, offset_mm=(42.0, -35.0), height_mm=3420.0)}


@pytest.fixture
def askew_lab(crater_file: Path, crater: CraterMap) -> Lab:
    return Lab.build(sim_settings(crater_file, **ASKEW), crater)


@pytest.mark.parametrize("which", ["ideal", "askew"])
def test_the_marker_renders_where_the_sims_own_camera_model_puts_it(
        which: str, lab: Lab, askew_lab: Lab, rng: np.random.Generator) -> None:
    lab = lab if which == "ideal" else askew_lab
    cam = lab.tracking
    for t, offset in ((0.0, (150.0, -420.0)), (30.0, (-600.0, 200.0)), (55.0, (500, 300))):
        robot = lab.robot(t)
        crane_xy = robot[:2] + offset
        lab.place_crane(crane_xy)  # disabled: it stays there
        np.testing.assert_allclose(lab.crane_world_at(t), crane_xy, atol=0.5)
        pixels, scale = cam.project(robot, crane_xy, lab.crane_frame)
        u, v = pixels[0]
        assert 0 < u < cam.width_px and 0 < v < cam.height_px, "the test keeps it in view"
        image = lab.tracking_frame(t, rng)
        assert image.shape == (cam.height_px, cam.width_px) and image.dtype == np.uint8
        nearest = min(_bright_spots(image), key=lambda s: np.hypot(s[0] - u, s[1] - v))
        assert np.hypot(nearest[0] - u, nearest[1] - v) < 1.0
        assert 1.5 < 9.5 * scale[0] < 10


def test_paper_equations_5_to_8_invert_the_ideal_rendering(lab: Lab) -> None:
    cam = lab.tracking
    robot = np.array([1234.0, -567.0, 210.0])
    crane_x, crane_y = 1000.0, -400.0
    (u, v), = cam.project(robot, np.array([crane_x, crane_y]), lab.crane_frame)[0]
    z = cam.height_mm - robot[2]
    b = thin_lens_image_distance_mm(cam.focal_mm, z)
    ref_u, ref_v = cam.width_px / 2, cam.height_px / 2
    x_err = z / b * (u - ref_u) * cam.pixel_mm
    y_err = -z / b * (v - ref_v) * cam.pixel_mm  # image rows grow towards world −y
    np.testing.assert_allclose([x_err + crane_x, y_err + crane_y], robot[:2], atol=1e-6)


def test_the_crane_counts_in_its_own_frame_and_the_world_sees_it_in_the_worlds(
        askew_lab: Lab) -> None:
    lab = askew_lab
    lab.place_crane(np.array([500.0, -200.0]))
    counted = lab.crane.position  # what its registers carry
    frame = lab.crane_frame
    assert counted == pytest.approx(frame.to_crane([500.0, -200.0]), abs=1e-6)
    assert counted[0] > 3000 and counted[1] > 3000, "from its home corner, y counted downwards"
    position, _ = lab.crane_state(0.0)
    assert position == pytest.approx([500.0, -200.0], abs=1e-6)
    marker = lab.crane_marker(0.0)
    assert marker == pytest.approx([500.0, -200.0, 3420.0], abs=1e-6)
    labels = lab.labels
    frame_0 = lab.mocap_frame(0)
    crane = frame_0.labelled[labels.index("crane")]
    assert np.hypot(*(crane[:2] - [500.0, -200.0])) < 5.0, "measured with the mocap's noise"


def test_stray_reflections_are_elongated(lab: Lab) -> None:
    assert lab.ground_glints, "the workspace has reflections"
    assert all(g.long_mm / g.short_mm > 2 for g in lab.ground_glints)
