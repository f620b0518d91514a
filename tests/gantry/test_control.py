"""The gantry's control step (pure): frames in, a safe setpoint out — no bus, no crane, no
clock."""

from __future__ import annotations

import numpy as np
import pytest

from common.heightmap import HeightMap
from services.gantry.control import Controller, Fix
from services.gantry.settings import GantrySettings
from services.sim.render import Blob, draw
from tests.gantry.camera import CAMERA, pixel_of

GROUND_MM, MARKER_MM = 100.0, 80.0
FLAT = HeightMap(np.full((3, 3), GROUND_MM, np.float32), -5000, -5000, 5000)
SETTINGS = GantrySettings(marker_height_mm=MARKER_MM, algorithm="basic", stale_after_s=0.6)


def _frame(markers_xy: list[tuple[float, float]], crane_xy: np.ndarray) -> np.ndarray:
    blobs = []
    for xy in markers_xy:
        u, v, r = pixel_of(np.array([*xy, GROUND_MM + MARKER_MM]), crane_xy)
        blobs.append(Blob(u, v, r, r))
    return draw(blobs, CAMERA.width_px, CAMERA.height_px, np.random.default_rng(0))


def test_a_marker_in_the_frame_becomes_the_robots_position_and_a_setpoint() -> None:
    control = Controller(SETTINGS, FLAT)
    crane = np.array([200.0, -100.0])
    robot = np.array([350.0, -20.0])
    step = control.step(10.0, (9.96, _frame([tuple(robot)], crane)), crane)
    assert step.detection is not None and step.frame_s == 9.96
    assert step.frame_shape == (CAMERA.height_px, CAMERA.width_px)
    assert step.measured_xyz is not None
    np.testing.assert_allclose(step.measured_xyz[:2], robot, atol=1.5)  # eq. 5–8
    assert step.estimate_s == 9.96 and not step.hold and step.reason == ""
    moved = step.setpoint - crane
    assert 0 < np.hypot(*moved) <= SETTINGS.max_speed_mm_s * 0.25 + 1e-6, "guarded"
    assert np.dot(moved, robot - crane) > 0, "towards the robot"


def test_without_new_frames_it_holds_once_the_estimate_is_stale() -> None:
    control = Controller(SETTINGS, FLAT)
    crane = np.array([0.0, 0.0])
    control.step(1.0, (0.96, _frame([(100.0, 0.0)], crane)), crane)
    assert not control.step(1.25, None, crane).hold, "0.29 s old: still used"
    stale = control.step(1.75, None, crane)
    assert stale.hold and "old" in stale.reason


def test_a_lost_marker_holds_and_says_so() -> None:
    control = Controller(SETTINGS, FLAT)
    crane = np.array([0.0, 0.0])
    control.step(1.0, (0.96, _frame([(100.0, 0.0)], crane)), crane)
    lost = control.step(1.25, (1.21, _frame([], crane)), crane)
    assert lost.hold and lost.reason == "no estimate" and lost.measured_xyz is None


def test_a_newest_frame_without_the_robot_gives_way_to_an_older_one_that_shows_it() -> None:
    """A spoofed or stray frame (a spot where the robot cannot be) that arrived last does not
    blind the gantry: the newest frame since the last step that shows the robot is used."""
    control = Controller(SETTINGS, FLAT)
    crane = np.array([0.0, 0.0])
    control.step(1.0, (0.96, _frame([(100.0, 0.0)], crane)), crane)
    spoofed = (1.24, _frame([(1500.0, 1500.0)], crane))
    real = (1.20, _frame([(120.0, 0.0)], crane))
    older = (1.10, _frame([(110.0, 0.0)], crane))
    step = control.step(1.25, spoofed, crane, older=[real, older])
    assert step.frame_s == 1.20 and step.measured_xyz is not None and not step.hold
    np.testing.assert_allclose(step.measured_xyz[:2], [120.0, 0.0], atol=1.5)
    alone = Controller(SETTINGS, FLAT)
    alone.step(1.0, (0.96, _frame([(100.0, 0.0)], crane)), crane)
    blinded = alone.step(1.25, spoofed, crane)
    assert blinded.hold and blinded.measured_xyz is None, "without the older frames"
    nothing = control.step(1.5, (1.49, _frame([], crane)), crane,
                           older=[(1.45, _frame([(2000.0, -2000.0)], crane))])
    assert nothing.frame_s == 1.49 and nothing.measured_xyz is None, "the newest, if none"


def test_a_frame_sent_again_with_the_spot_moved_yields_to_the_one_the_motion_capture_agrees_with(
        ) -> None:
    """A real frame sent again with its spot drifted a little (same capture time, passes the
    gate) once dragged the crane 827 mm: of frames captured together the one nearest the
    motion capture's robot is used; a newer frame that disagrees beyond ``fix_check_mm``
    yields to an older one that agrees; without the motion capture, the newest."""
    crane = np.array([0.0, 0.0])
    robot = Fix(1.2, np.array([120.0, 0.0]))
    for drift in (60.0, 250.0):  # within the gate and the check's tolerance; beyond it
        control = Controller(SETTINGS, FLAT)
        control.step(1.0, (0.96, _frame([(100.0, 0.0)], crane)), crane, fix=robot)
        copy = (1.20, _frame([(120.0 + drift, 0.0)], crane))
        real = (1.20, _frame([(120.0, 0.0)], crane))
        step = control.step(1.25, copy, crane, fix=robot, older=[real])
        assert step.measured_xyz is not None and step.frame_s == 1.20
        np.testing.assert_allclose(step.measured_xyz[:2], [120.0, 0.0], atol=1.5)
    control = Controller(SETTINGS, FLAT)
    control.step(1.0, (0.96, _frame([(100.0, 0.0)], crane)), crane, fix=robot)
    newer_off = (1.24, _frame([(300.0, 0.0)], crane))  # 180 mm from the motion capture
    step = control.step(1.25, newer_off, crane, fix=robot,
                        older=[(1.20, _frame([(121.0, 0.0)], crane))])
    assert step.frame_s == 1.20, "the older frame that agrees"
    blind = Controller(SETTINGS, FLAT)  # no motion capture: the newest, as the paper
    blind.step(1.0, (0.96, _frame([(100.0, 0.0)], crane)), crane)
    step = blind.step(1.25, (1.20, _frame([(160.0, 0.0)], crane)), crane,
                      older=[(1.20, _frame([(120.0, 0.0)], crane))])
    assert step.measured_xyz is not None
    np.testing.assert_allclose(step.measured_xyz[:2], [160.0, 0.0], atol=1.5)


def test_of_several_spots_it_keeps_the_one_nearest_the_last() -> None:
    control = Controller(SETTINGS, FLAT)
    crane = np.array([0.0, 0.0])
    control.step(1.0, (0.96, _frame([(50.0, 40.0)], crane)), crane)
    step = control.step(1.25, (1.21, _frame([(60.0, 40.0), (-300.0, 250.0)], crane)), crane)
    assert step.measured_xyz is not None
    np.testing.assert_allclose(step.measured_xyz[:2], [60.0, 40.0], atol=1.5)


def test_after_a_restart_the_setpoint_starts_from_where_the_crane_stands() -> None:
    control = Controller(SETTINGS, FLAT)
    crane = np.array([0.0, 0.0])
    for k in range(6):  # ramp towards a robot far away
        control.step(k * 0.25, (k * 0.25 - 0.04, _frame([(250.0, 0.0)], crane)), crane)
    control.restart()  # e.g. the crane stopped on its own
    stood = np.array([-200.0, 0.0])
    step = control.step(1.75, None, stood)
    assert np.hypot(*(step.setpoint - stood)) <= SETTINGS.max_speed_mm_s * 0.25 + 1e-6


def test_a_spot_far_from_where_the_robot_should_be_is_not_the_robot() -> None:
    control = Controller(SETTINGS.model_copy(update={"marker_gate_mm": 150.0}), FLAT)
    crane = np.array([0.0, 0.0])
    control.step(1.0, (0.96, _frame([(0.0, 0.0)], crane)), crane)
    control.step(1.25, (1.21, _frame([(100.0, 0.0)], crane)), crane)  # 400 mm/s along x
    # the robot is gone from view; a reflection lies 500 mm from where it should be
    lost = control.step(1.5, (1.46, _frame([(-300.0, 0.0)], crane)), crane)
    assert lost.measured_xyz is None and lost.rejected_mm == pytest.approx(500.0, abs=5.0)
    # a reflection nearer the last pixel than the robot (now 200 mm on) is passed over
    control = Controller(SETTINGS.model_copy(update={"marker_gate_mm": 150.0}), FLAT)
    control.step(1.0, (0.96, _frame([(0.0, 0.0)], crane)), crane)
    control.step(1.25, (1.21, _frame([(100.0, 0.0)], crane)), crane)
    step = control.step(1.5, (1.46, _frame([(200.0, 0.0), (20.0, 0.0)], crane)), crane)
    assert step.measured_xyz is not None
    np.testing.assert_allclose(step.measured_xyz[:2], [200.0, 0.0], atol=1.5)


def test_a_lost_marker_is_looked_for_where_the_motion_capture_sees_the_robot() -> None:
    s = SETTINGS.model_copy(update={"reacquire_after_s": 1.0, "reacquire_speed_mm_s": 100.0})
    control = Controller(s, FLAT)
    crane = np.array([0.0, 0.0])
    control.step(1.0, (0.96, _frame([(50.0, 0.0)], crane)), crane)
    fix = Fix(1.9, np.array([1500.0, 0.0]))  # out of view: 1.5 m away
    early = control.step(1.5, (1.46, _frame([], crane)), crane, fix)
    assert early.hold and not early.reacquiring, "lost only 0.5 s: hold"
    steps = [control.step(2.0 + 0.25 * k, (1.96 + 0.25 * k, _frame([], crane)), crane,
                          Fix(1.95 + 0.25 * k, fix.xy_mm)) for k in range(6)]
    assert all(st.reacquiring and not st.hold for st in steps)
    moved = np.diff([st.setpoint[0] for st in steps])
    assert np.all(moved > 0) and np.all(moved <= 100.0 * 0.25 + 1e-6), "towards it, slowly"
    stale_fix = control.step(3.75, (3.71, _frame([], crane)), crane, Fix(2.0, fix.xy_mm))
    assert stale_fix.hold and not stale_fix.reacquiring, "an old fix is not followed"


def test_frames_that_disagree_with_the_motion_capture_do_not_steer_the_crane() -> None:
    """Spoofed frames (any client could publish them in an unsecured lab: 428 of them once
    pulled the crane 1.57 m off the robot) drag the marker away 40 mm a frame; the motion
    capture keeps seeing the robot where it stands. A spot that has disagreed with the fix by
    more than ``fix_check_mm`` for ``check_window_s`` is not used, nor one ``mocap_gate_mm``
    from it, so the crane stays near the robot."""
    control = Controller(SETTINGS, FLAT)
    robot = np.array([0.0, 0.0])
    crane = robot.copy()
    farthest = 0.0
    for k in range(60):
        t = 1.0 + 0.25 * k
        spoof = robot + [40.0 * k, 0.0]
        step = control.step(t, (t - 0.04, _frame([tuple(spoof)], crane)), crane,
                            fix=Fix(t - 0.01, robot))
        crane = step.setpoint
        farthest = max(farthest, float(np.hypot(*(crane - robot))))
        if k * 40.0 > SETTINGS.mocap_gate_mm + 40.0:  # refused (or out of view by now)
            assert step.measured_xyz is None
            assert step.rejected_mm is not None or not step.detection.markers  # type: ignore[union-attr]
    drift_mm = 40.0 / 0.25 * SETTINGS.check_window_s  # the spot's drift within the window
    assert farthest < SETTINGS.fix_check_mm + drift_mm + 50.0, farthest
    unchecked = Controller(SETTINGS.model_copy(update={"mocap_gate_mm": 0.0,
                                                       "fix_check_mm": 0.0}), FLAT)
    crane = robot.copy()
    for k in range(60):  # the same frames without the check: the crane follows the spoof
        t = 1.0 + 0.25 * k
        crane = unchecked.step(t, (t - 0.04, _frame([tuple(robot + [40.0 * k, 0.0])], crane)),
                               crane, fix=Fix(t - 0.01, robot)).setpoint
    assert np.hypot(*(crane - robot)) > 1500.0
