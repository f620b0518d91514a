"""The follower's rules and where a preview puts the robot (pure parts of the PTZ service)."""

from __future__ import annotations

import numpy as np
import pytest

from common import messages as m
from common.camera import Pose, PtzLimits, head_pose, project
from common.ptz_lens import PtzLens, ZoomCurve, axis_215, axis_215_px
from common.volume import Volume
from services.ptz.aim import aim_at, predict
from services.ptz.follow import Follower
from services.ptz.preview import robot_view

MOUNT = Pose(3550.0, 1090.0, 2190.0, 180.0, 30.0, 165.0)
ROBOT = np.array([0.0, -900.0, 80.0])
STILL = np.zeros(3)
WIDE = axis_215(3.8)


def test_the_follower_aims_where_the_robot_will_be_after_the_cameras_latency() -> None:
    follower = Follower(latency_s=0.25, min_interval_s=0.1)
    velocity = np.array([290.0, 0.0, 0.0])
    command = follower.command(100.05, ROBOT, velocity, 100.0, MOUNT)
    assert command is not None and command.measured_s == 100.0
    ahead = predict(ROBOT, velocity, 0.05 + 0.25, max_ahead_s=1.0)
    assert (command.pan_deg, command.tilt_deg) == pytest.approx(aim_at(ahead, MOUNT))


def test_the_follower_keeps_quiet_within_its_dead_band_its_rate_and_outside_its_volume() -> None:
    follower = Follower(deadband_deg=0.3, min_interval_s=0.1, volume=Volume(x_max_mm=3000.0),
                        max_age_s=1.0)
    assert follower.command(100.0, ROBOT, STILL, 100.0, MOUNT) is not None
    assert follower.command(100.05, ROBOT + [500, 0, 0], STILL, 100.05, MOUNT) is None  # rate
    assert follower.command(100.2, ROBOT + [1, 0, 0], STILL, 100.2, MOUNT) is None  # dead band
    assert follower.command(100.4, np.array([4000.0, 0, 80]), STILL, 100.4, MOUNT) is None
    assert follower.command(102.0, ROBOT + [500, 0, 0], STILL, 100.6, MOUNT) is None  # stale
    assert follower.command(102.1, ROBOT + [500, 0, 0], STILL, 102.1, MOUNT) is not None
    follower.forget()
    assert follower.command(102.15, ROBOT + [500, 0, 0], STILL, 102.15, MOUNT) is not None


def test_the_services_follower_ignores_positions_far_outside_the_crater() -> None:
    """As the PTZ service builds it (the lab's volume by default): a robot sample 90 m away
    (a tracker's glitch) moves nothing."""
    follower = Follower()
    assert follower.command(100.0, np.array([90_000.0, 0.0, 0.0]), STILL, 100.0, MOUNT) is None
    assert follower.command(100.2, ROBOT, STILL, 100.2, MOUNT) is not None


def test_the_follower_stays_within_the_cameras_limits() -> None:
    follower = Follower(limits=PtzLimits(min_pan=-10.0, max_pan=10.0))
    command = follower.command(100.0, np.array([-3000.0, 2500.0, 80.0]), STILL, 100.0, MOUNT)
    assert command is not None and -10.0 <= command.pan_deg <= 10.0


def _robot(at_s: float, velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)
           ) -> m.RobotPosition:
    return m.RobotPosition(measured_s=at_s, label="robot", x_mm=ROBOT[0], y_mm=ROBOT[1],
                           z_mm=ROBOT[2], vx_mm_s=velocity[0], vy_mm_s=velocity[1],
                           vz_mm_s=velocity[2])


def test_a_preview_puts_the_robot_where_it_will_be_when_the_picture_is_taken() -> None:
    pan, tilt = aim_at(ROBOT, MOUNT)
    robot = _robot(100.0, (290.0, 0.0, 0.0))
    found = robot_view(MOUNT, robot, pan, tilt, WIDE, at_s=100.5)[0]
    expected = project((ROBOT + [145.0, 0.0, 0.0])[None, :], head_pose(MOUNT, pan, tilt),
                       axis_215(3.8))[0]
    assert found == pytest.approx(expected.tolist(), abs=0.06)  # rounded to 0.1 px
    capped = robot_view(MOUNT, robot, pan, tilt, WIDE, at_s=160.0)[0]
    assert capped == robot_view(MOUNT, robot, pan, tilt, WIDE, at_s=101.0)[0]
    centre = robot_view(MOUNT, _robot(100.0), pan, tilt, WIDE, at_s=100.0)[0]
    assert centre == pytest.approx([352.0, 288.0], abs=0.2)  # aimed at it: the image centre


def test_no_robot_pixel_without_a_pose_a_robot_or_with_the_robot_behind_the_camera() -> None:
    assert robot_view(None, _robot(1.0), 0.0, 0.0, WIDE, 1.0)[0] is None
    assert robot_view(MOUNT, None, 0.0, 0.0, WIDE, 1.0)[0] is None
    pan, tilt = aim_at(ROBOT, MOUNT)
    assert robot_view(MOUNT, _robot(1.0), pan + 180.0, tilt, WIDE, 1.0)[0] is None


def test_a_preview_says_how_large_the_robot_marker_appears() -> None:
    """Aimed at the robot, its 19 mm marker's radius is fy · 9.5 mm / distance (the sim draws
    it so): about 1.3 px at 5.3 m at the widest zoom."""
    pan, tilt = aim_at(ROBOT, MOUNT)
    distance = float(np.linalg.norm(ROBOT - MOUNT.position))
    fy = axis_215(3.8).fy_px
    radius = robot_view(MOUNT, _robot(100.0), pan, tilt, WIDE, 100.0, 19.0)[1]
    assert radius is not None and radius == pytest.approx(fy * 9.5 / distance, abs=0.01)
    twice = robot_view(MOUNT, _robot(100.0), pan, tilt, WIDE.with_focal(2 * WIDE.focal_px),
                       100.0, 19.0)[1]
    assert twice == pytest.approx(2 * radius, abs=0.02)
    assert robot_view(None, _robot(1.0), pan, tilt, WIDE, 1.0, 19.0)[1] is None
    assert robot_view(MOUNT, _robot(1.0), pan + 180.0, tilt, WIDE, 1.0, 19.0)[1] is None


def test_at_a_long_zoom_the_dead_band_shrinks_with_the_picture() -> None:
    """0.1° is nothing in a 50° picture and 4 % of a 2.5° one."""
    for zoom, moves in ((1, False), (9999, True)):
        follower = Follower(deadband_deg=0.3, min_interval_s=0.0, zoom=zoom)
        first = follower.command(100.0, ROBOT, STILL, 100.0, MOUNT)
        assert first is not None
        pan, tilt = aim_at(ROBOT, MOUNT)
        distance = float(np.linalg.norm(ROBOT - MOUNT.position))
        aside = ROBOT + np.array([0.0, distance * np.radians(0.1), 0.0])  # ≈ 0.1° away
        again = follower.command(100.2, aside, STILL, 100.2, MOUNT)
        assert (again is not None) == moves, (zoom, pan, tilt)


def test_a_robot_off_the_centre_of_a_long_zoom_makes_the_camera_zoom_out_and_back() -> None:
    lens = PtzLens(ZoomCurve((1, 6000, 9999), (3.8, 9.0, 46.0)).scaled(axis_215_px(1.0)))
    follower = Follower(min_interval_s=0.0, zoom=9999, lens=lens)
    pan, tilt = aim_at(ROBOT, MOUNT)
    follower.seen(pan + 2.0, tilt, 9999)  # the camera is 2° behind: off a ±1.7° picture
    out = follower.command(100.0, ROBOT, STILL, 100.0, MOUNT)
    assert out is not None and out.zoom < 9999
    assert follower.half_view_deg(out.zoom) >= 2.0 / follower.central
    follower.seen(pan + 0.5, tilt, out.zoom)  # closer, not yet re-centred at 9999's scale
    closer = follower.command(100.1, ROBOT + [0, 0, 30.0], STILL, 100.1, MOUNT)
    assert closer is not None and closer.zoom == out.zoom
    follower.seen(pan, tilt, out.zoom)  # re-centred: back to the wanted zoom
    back = follower.command(100.2, ROBOT, STILL, 100.2, MOUNT)
    assert back is not None and back.zoom == 9999
