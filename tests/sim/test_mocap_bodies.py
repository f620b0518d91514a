"""6DOF bodies from the simulated QTM, read by the unmodified qtm-rt client: the robot and the
wand as bodies (6d and 6deuler), their markers in 3d, parameters QTM does not have refused."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from typing import Any

import numpy as np
import pytest
import qtm_rt

from common.camera import rotation_xyz
from services.sim.bodies import ROBOT_POINTS_MM, fit, place
from services.sim.lab import Lab
from tests.sim.test_mocap import _run, _stream


def _matrix(rotation: Any) -> np.ndarray:
    return np.array(rotation.matrix).reshape(3, 3).T  # QTM sends it column by column


def test_the_robot_body_follows_the_robot_and_faces_where_it_goes(lab: Lab) -> None:
    packets = _run(lab, lambda port: _stream(port, ["3d", "6d", "6deuler"], count=150),
                   start_s=4.0)
    robot_index = [b.name for b in lab.bodies].index("robot")
    errors: list[float] = []
    turned: list[float] = []
    lost = 0
    for packet in packets:
        info, bodies = packet.get_6d()
        _, euler = packet.get_6d_euler()
        assert info.body_count == len(lab.bodies) == 2
        position, rotation = bodies[robot_index]
        t = packet.framenumber / lab.settings.mocap.rate_hz
        xyz = np.array([position.x, position.y, position.z])
        if np.isnan(xyz).any():
            lost += 1
            assert np.isnan(_matrix(rotation)).all(), "a lost body is NaN, never zero"
            continue
        errors.append(float(np.linalg.norm(xyz - lab.robot(t))))
        r = _matrix(rotation)
        np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-5)
        velocity = lab.robot_velocity(t)
        if np.hypot(*velocity[:2]) > 50:
            heading = np.degrees(np.arctan2(r[1, 0], r[0, 0]))
            turned.append(abs((heading - np.degrees(np.arctan2(velocity[1], velocity[0]))
                               + 180) % 360 - 180))
        angles = euler[robot_index][1]
        np.testing.assert_allclose(rotation_xyz(angles.a1, angles.a2, angles.a3), r, atol=1e-4)
    assert np.sqrt(np.mean(np.square(errors))) < 1.5, "the body's origin is the robot marker"
    assert turned and max(turned) < 3.0, "the body's x axis points where the robot moves"
    assert lost < 0.1 * len(packets)


def test_the_bodys_markers_in_3d_fit_its_pose(lab: Lab) -> None:
    packets = _run(lab, lambda port: _stream(port, ["3d", "6d"], count=50))
    labels = lab.labels
    robot_body, names = lab.body_points[0]
    rows = [labels.index(name) for name in names]
    checked = 0
    for packet in packets:
        _, markers = packet.get_3d_markers()
        measured = np.array([[markers[i].x, markers[i].y, markers[i].z] for i in rows])
        position, rotation = packet.get_6d()[1][0]
        if np.isnan(position.x):
            continue
        pose = (np.array([position.x, position.y, position.z]), _matrix(rotation))
        seen = np.all(np.isfinite(measured), axis=1)
        assert np.linalg.norm(place(ROBOT_POINTS_MM, *pose)[seen] - measured[seen],
                              axis=1).max() < 5.0
        checked += 1
    assert checked > 30


def test_the_wand_body_is_lost_while_the_robot_runs(lab: Lab) -> None:
    assert lab.wand_position(1.0) is None, "this lab's robot runs from the start"
    packets = _run(lab, lambda port: _stream(port, ["6d"], count=30))
    wand = [b.name for b in lab.bodies].index("wand")
    assert packets and all(np.isnan(p.get_6d()[1][wand][0].x) for p in packets)


def test_body_parameters_name_the_bodies_and_their_points(lab: Lab) -> None:
    async def client(port: int) -> str:
        conn = await qtm_rt.connect("127.0.0.1", port=port, version="1.25")
        assert conn is not None
        try:
            return await conn.get_parameters(parameters=["6d"])
        finally:
            conn.disconnect()

    root = ET.fromstring(_run(lab, client))
    assert root.find("The_3D") is None, "only what was asked for"
    assert [b.text for b in root.findall("*/Body/Name")] == ["robot", "wand"]
    points = root.findall("The_6D/Body")[0].findall("Points/Point")
    assert [p.get("Name") for p in points] == ["robot", "robot - 2", "robot - 3", "robot - 4"]
    model = np.array([[float(p.get(a, "nan")) for a in "XYZ"] for p in points])
    np.testing.assert_allclose(model, ROBOT_POINTS_MM)


@pytest.mark.parametrize("group", ["calibration", "image", "skeleton", "analog", "force"])
def test_parameters_it_does_not_have_are_refused(lab: Lab, group: str) -> None:
    async def client(port: int) -> str:
        conn = await qtm_rt.connect("127.0.0.1", port=port, version="1.25")
        assert conn is not None
        try:
            with pytest.raises(qtm_rt.QRTCommandException) as refused:
                await conn.get_parameters(parameters=[group])
            return str(refused.value)
        finally:
            conn.disconnect()

    assert group in _run(lab, client)


def test_a_fit_needs_three_markers() -> None:
    pose = (np.array([100.0, -50.0, 20.0]), rotation_xyz(0, 0, 30))
    points = place(ROBOT_POINTS_MM, *pose)
    points[:1] = np.nan
    fitted = fit(ROBOT_POINTS_MM, points)
    assert fitted is not None
    np.testing.assert_allclose(fitted[0], pose[0], atol=1e-9)
    np.testing.assert_allclose(fitted[1], pose[1], atol=1e-9)
    points[1] = np.nan
    assert fit(ROBOT_POINTS_MM, points) is None
