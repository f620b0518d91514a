"""The sim's PTZ head geometry (its own truth): with its axes meeting at the optical centre it
is the PTZ service's model; with a tilt axis off the pan axis and a lens in front of it, the
camera's centre moves as the head turns."""

from __future__ import annotations

import numpy as np
import pytest

from common.camera import Pose, head_pose
from services.sim.ptz import PtzHead
from services.sim.settings import PtzCameraSettings

MOUNT = Pose(3550, 1090, 2190, 180, 30, 165)


def test_a_head_whose_axes_meet_at_the_lens_is_the_services_model() -> None:
    head = PtzHead(MOUNT)
    rng = np.random.default_rng(5)
    for pan, tilt in rng.uniform([-170, -90], [170, 0], (20, 2)):
        truth, model = head.pose_at(pan, tilt), head_pose(MOUNT, pan, tilt)
        assert np.allclose(truth.rotation, model.rotation, atol=1e-12)
        assert np.allclose(truth.position, model.position, atol=1e-9)


def test_the_lens_in_front_of_the_tilt_axis_swings_with_pan_and_tilt() -> None:
    """60 mm in front of the axes: half a turn of pan moves the centre 120 mm across the
    mount's horizontal plane; the view's direction is the model's at every pan and tilt."""
    head = PtzHead(Pose(0, 0, 2000, 180, 0, 0), optical_centre_mm=(60.0, 0.0, 0.0))
    home, turned = head.pose_at(0, 0), head.pose_at(180, 0)
    assert np.allclose(home.position, [60.0, 0.0, 2000.0], atol=1e-9)
    assert np.linalg.norm(turned.position - home.position) == pytest.approx(120.0)
    down = head.pose_at(0, -90)  # tilted straight down (z down in the image: x → world -z)
    assert np.allclose(down.position, [0.0, 0.0, 2000.0 - 60.0], atol=1e-9)
    for pan, tilt in [(30, -20), (-120, -60)]:
        assert np.allclose(head.pose_at(pan, tilt).rotation,
                           head_pose(head.mount, pan, tilt).rotation, atol=1e-12)


def test_a_tilt_axis_off_the_pan_axis_turns_with_pan_only() -> None:
    head = PtzHead(Pose(0, 0, 2000, 180, 0, 0), tilt_axis_mm=(0.0, 0.0, 40.0))
    for tilt in (0, -45, -90):  # the tilt axis 40 mm below the mount's point (z down)
        assert np.allclose(head.pose_at(0, tilt).position, [0.0, 0.0, 1960.0], atol=1e-9)


def test_a_lab_file_sets_the_offsets_and_bounds_them() -> None:
    cam = PtzCameraSettings(name="ptz1", port=8081, **MOUNT.fields(), tilt_axis_mm=(0, 10, 30),
                            optical_centre_mm=(55, 0, -5))
    assert cam.tilt_axis_mm == (0, 10, 30) and cam.optical_centre_mm == (55, 0, -5)
    with pytest.raises(ValueError, match="within 500 mm"):
        PtzCameraSettings(name="ptz1", port=8081, **MOUNT.fields(),
                          optical_centre_mm=(900, 0, 0))
