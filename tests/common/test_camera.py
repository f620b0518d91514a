"""The camera model (paper eq. 1–3, Table 1) against hand-computed cases."""

from __future__ import annotations

import numpy as np
import pytest

from common.camera import (
    Pose,
    euler_xyz_deg,
    project,
    rotation_xyz,
    thin_lens_image_distance_mm,
)
from common.ptz_lens import axis_215


def test_axis_215_intrinsics_of_table_1() -> None:
    intr = axis_215(3.8)
    assert intr.fy_px == pytest.approx(3.8 / (3.6 / 704))
    assert intr.fz_px == pytest.approx(3.8 / (2.7 / 576))
    assert (intr.cy_px, intr.cz_px) == (352, 288)


def test_identity_pose_projects_by_equation_3() -> None:
    intr = axis_215(3.8)
    uv = project(np.array([[2000.0, 100.0, -50.0]]), Pose(0, 0, 0, 0, 0, 0), intr)
    assert uv[0, 0] == pytest.approx(intr.fy_px * 100 / 2000 + 352)
    assert uv[0, 1] == pytest.approx(intr.fz_px * -50 / 2000 + 288)


def test_rotation_order_is_rx_ry_rz() -> None:
    r = rotation_xyz(90, 0, 0) @ rotation_xyz(0, 90, 0)
    np.testing.assert_allclose(rotation_xyz(90, 90, 0), r, atol=1e-12)
    # Rz(90°) turns the optical axis x onto y.
    np.testing.assert_allclose(rotation_xyz(0, 0, 90) @ [1, 0, 0], [0, 1, 0], atol=1e-12)


def test_pose_maps_camera_to_world_and_back() -> None:
    pose = Pose(3413, 1093, 2163, 197, 27, 159)  # the paper's optimum (Table 2)
    points = np.array([[100.0, -20.0, 5.0], [4000.0, 300.0, -200.0]])
    np.testing.assert_allclose(pose.to_camera(pose.to_world(points)), points, atol=1e-9)
    np.testing.assert_allclose(pose.to_world(np.zeros((1, 3)))[0], pose.position)


def test_paper_estimate_looks_at_the_crater_centre() -> None:
    pose = Pose(3550, 1090, 2190, 180, 30, 165)  # Table 2, "estimated"
    axis = pose.rotation @ [1, 0, 0]
    hit = pose.position + axis * (-pose.z_mm / axis[2])  # where the optical axis meets z = 0
    assert np.hypot(*hit[:2]) < 300


def test_points_behind_the_camera_do_not_project() -> None:
    uv = project(np.array([[-10.0, 0, 0], [10.0, 0, 0]]), Pose(0, 0, 0, 0, 0, 0),
                 axis_215(3.8))
    assert np.isnan(uv[0]).all() and np.isfinite(uv[1]).all()


@pytest.mark.parametrize("angles", [(197, 27, 159), (10, -80, 33), (-45, 10, 170), (0, 0, 0)])
def test_euler_angles_round_trip(angles: tuple[float, float, float]) -> None:
    r = rotation_xyz(*angles)
    np.testing.assert_allclose(rotation_xyz(*euler_xyz_deg(r)), r, atol=1e-12)


def test_thin_lens_equation_5() -> None:
    assert thin_lens_image_distance_mm(8.0, 3000.0) == pytest.approx(1 / (1 / 8 - 1 / 3000))
    with pytest.raises(ValueError):
        thin_lens_image_distance_mm(8.0, 5.0)


def test_mount_pose_undoes_head_pose() -> None:
    from common.camera import head_pose, mount_pose

    mount = Pose(3550.0, 1090.0, 2190.0, 180.0, 30.0, 165.0)
    for pan, tilt in [(0.0, 0.0), (35.0, -20.0), (-170.0, 60.0)]:
        back = mount_pose(head_pose(mount, pan, tilt), pan, tilt)
        assert np.allclose(back.rotation, mount.rotation, atol=1e-12)
        assert np.allclose(back.position, mount.position)


def test_quaternion_of_a_rotation_matches_scipy_and_keeps_w_non_negative() -> None:
    from scipy.spatial.transform import Rotation

    from common.camera import quaternion_wxyz
    for rotation in [*Rotation.random(500, random_state=4).as_matrix(),
                     np.eye(3), np.diag([1.0, -1.0, -1.0]), np.diag([-1.0, -1.0, 1.0])]:
        q = np.array(quaternion_wxyz(rotation))
        x, y, z, w = Rotation.from_matrix(rotation).as_quat()
        expected = np.array([w, x, y, z]) * (1 if w >= 0 else -1)
        assert q[0] >= 0 and abs(np.linalg.norm(q) - 1) < 1e-12
        if abs(w) > 1e-9:  # at w = 0 both signs are the same rotation
            np.testing.assert_allclose(q, expected, atol=1e-12)
        np.testing.assert_allclose(Rotation.from_quat([*q[1:], q[0]]).as_matrix(), rotation,
                                   atol=1e-12)
