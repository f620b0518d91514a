"""The PTZ service's rules without a camera or a bus (services/ptz/control.py)."""

from __future__ import annotations

import pytest

from common import messages as m
from common.camera import Pose, PtzLimits
from services.ptz.control import HAND_MAX_AGE_S, RETRY_FIRST_S, RETRY_MAX_S, PtzControl
from services.ptz.follow import Follower
from services.ptz.override import ManualOverride
from services.ptz.pointing import InfraredSchedule, PointingCheck

MOUNT = Pose(3550.0, 1090.0, 2190.0, 180.0, 30.0, 165.0)


def _control() -> PtzControl:
    return PtzControl(Follower(min_interval_s=0.1), ManualOverride(5.0, 30.0),
                      PointingCheck(3.0, 2), max_future_s=1.0)


def _pose(measured_s: float = 100.0, version: int = 1, rz_deg: float = 165.0) -> m.CameraPose:
    return m.CameraPose(measured_s=measured_s, camera="ptz1",
                        **(MOUNT.fields() | {"rz_deg": rz_deg}), focal_px=743.1,
                        mean_error_px=0.5, passpoints=100, version=version)


def _robot(t: float, x: float = 0.0) -> m.RobotPosition:
    return m.RobotPosition(measured_s=t, label="robot", x_mm=x, y_mm=-900.0, z_mm=80.0,
                           vx_mm_s=0.0, vy_mm_s=0.0, vz_mm_s=0.0)


def _following(now: float = 200.0) -> PtzControl:
    control = _control()
    assert control.take_pose(_pose(), now) == "taken"
    control.camera_limits(PtzLimits(), (704, 576))
    return control


def test_the_calibration_services_answer_is_taken_whatever_its_version_but_not_from_the_future(
        ) -> None:
    """The pose comes from the calibration service's answer (pose_source.py), so its version
    orders nothing: a lower one after a discard or a fresh data folder is the pose."""
    control = _control()
    assert control.take_pose(_pose(measured_s=300.0), now=200.0) == "future"
    assert control.pose is None
    assert control.take_pose(_pose(measured_s=100.0, version=2), now=200.0) == "taken"
    assert control.take_pose(_pose(measured_s=100.0, version=2), now=250.0) == "same"
    assert control.take_pose(_pose(measured_s=150.0, version=1, rz_deg=160.0), 200.0) == "taken"
    assert control.pose_msg is not None and control.pose is not None
    assert control.pose == Pose.of(control.pose_msg) and control.pose.rz_deg == 160.0


def test_a_new_pose_clears_the_pointing_check_the_same_one_does_not() -> None:
    control = _following()
    control.pointing.error_deg = 40.0
    control.take_pose(_pose(), 200.0)
    assert control.pointing.error_deg == 40.0
    control.take_pose(_pose(measured_s=101.0), 200.0)
    assert control.pointing.error_deg is None


def test_no_command_without_a_pose_or_limits_while_failing_or_calibrating() -> None:
    control = _control()
    assert control.command(_robot(200.0), 200.0, calibrating=False) is None  # no pose
    control.take_pose(_pose(), 200.0)
    assert control.command(_robot(200.0), 200.0, calibrating=False) is None  # no limits
    control.camera_limits(PtzLimits(), (704, 576))
    assert control.command(_robot(200.0), 200.0, calibrating=True) is None
    control.failed(200.0)
    assert control.limits is None, "asked again after a failure"
    control.camera_limits(PtzLimits(), (704, 576))
    assert control.command(_robot(200.2), 200.2, calibrating=False) is None  # waiting
    command = control.command(_robot(200.6), 200.6, calibrating=False)
    assert command is not None and command.measured_s == 200.6


def test_commands_follow_the_robot_at_most_command_hz() -> None:
    control = _following()
    first = control.command(_robot(200.0, x=0.0), 200.0, calibrating=False)
    assert first is not None
    control.commanded(200.0, first)
    assert control.command(_robot(200.05, x=300.0), 200.05, calibrating=False) is None
    second = control.command(_robot(200.15, x=300.0), 200.15, calibrating=False)
    assert second is not None and second.pan_deg != pytest.approx(first.pan_deg, abs=0.5)


def test_the_wait_after_failures_doubles_up_to_the_limit_and_resets_on_an_answer() -> None:
    control, now, waits = _following(), 0.0, []
    for _ in range(6):
        control.failed(now)
        waits.append(round(control.retry_at - now, 3))
        assert not control.may_try(now) and control.may_try(control.retry_at)
        now = control.retry_at
    assert waits == [0.5, 1.0, 2.0, 4.0, RETRY_MAX_S, RETRY_MAX_S]
    control.answered()
    assert control.retry_s == RETRY_FIRST_S


def test_the_status_of_each_state() -> None:
    control = _control()
    state = control.status(200.0, 0.0, 0.0, calibrating=False)
    assert (state.status, state.health) == ("waiting_for_pose", "degraded")
    assert "pose" in state.health_why
    control.take_pose(_pose(), 200.0)
    control.camera_limits(PtzLimits(), (704, 576))
    assert control.status(200.5, 0.0, 0.0, calibrating=False).status == "idle"
    control.command(_robot(201.0), 201.0, calibrating=False)
    tracking = control.status(201.0, 0.0, 0.0, calibrating=False)
    assert (tracking.status, tracking.health) == ("tracking", "ok")
    assert tracking.aim_error_deg > 1.0  # the camera at (0, 0) does not look at the robot
    assert control.status(201.5, 0.0, 0.0, calibrating=True).status == "calibrating"


def test_someone_elses_move_pauses_following_and_says_manual() -> None:
    control = _following()
    control.status(199.9, 0.0, 0.0, calibrating=False)  # where it was seen before
    command = control.command(_robot(200.0), 200.0, calibrating=False)
    assert command is not None
    control.commanded(200.0, command)
    control.status(200.2, command.pan_deg, command.tilt_deg, calibrating=False)
    moved = control.status(200.5, command.pan_deg + 40.0, command.tilt_deg, calibrating=False)
    assert moved.status == "manual" and control.manual
    assert control.command(_robot(201.0, x=500.0), 201.0, calibrating=False) is None
    back = control.status(231.0, command.pan_deg + 40.0, command.tilt_deg, calibrating=False)
    assert back.status == "tracking" and not control.manual
    assert control.command(_robot(231.0, x=500.0), 231.0, calibrating=False) is not None


def test_an_infrared_check_is_due_with_a_pose_and_again_for_a_new_pose_or_a_lost_camera(
        ) -> None:
    control = _control()
    control.infrared = InfraredSchedule(every_s=300.0, confirm_s=2.0)
    assert not control.infrared_due(200.0, recording=False), "nothing to check without a pose"
    assert control.take_pose(_pose(), 210.0) == "taken"
    assert control.infrared_due(210.0, recording=False)
    control.infrared.judged()
    assert not control.infrared_due(211.0, recording=False), "taken: the next in minutes"
    assert control.take_pose(_pose(measured_s=101.0), 220.0) == "taken"
    assert control.infrared_due(220.0, recording=False), "a new pose is checked at once"
    control.failed(230.0)  # a reboot may have moved it: checked when it is back
    assert control.infrared_due(231.0, recording=False)
    assert control.take_pose(_pose(measured_s=102.0), 240.0) == "taken"
    assert not control.infrared_due(240.0, recording=True), "a recording runs"
    assert control.infrared_due(241.0, recording=False)


def _hand(action: m.HandAction, sent_s: float, operator: str = "ada (web 10.0.0.5)") -> m.PtzHand:
    return m.PtzHand(measured_s=sent_s, camera="ptz1", action=action,
                     operator=operator, pan_deg=10.0 if action == "move" else None)


def test_a_hand_holds_the_camera_and_follow_lets_it_go() -> None:
    control = _control()
    assert control.take_hand(_hand("hold", 100.0), 100.2, calibrating=False) is None
    assert control.held_by == "ada (web 10.0.0.5)"
    assert control.take_hand(_hand("follow", 101.0), 101.0, calibrating=False) is None
    assert control.held_by == ""


def test_a_hand_sent_too_long_ago_is_not_taken() -> None:
    control = _control()
    late = control.take_hand(_hand("move", 100.0), 100.0 + HAND_MAX_AGE_S + 0.5,
                             calibrating=False)
    assert late is not None and "s ago" in late and control.held_by == ""
    early = control.take_hand(_hand("hold", 100.0), 100.0 - HAND_MAX_AGE_S - 0.5,
                              calibrating=False)  # a sender whose clock is ahead
    assert early is not None and control.held_by == ""


@pytest.mark.parametrize("action", ["move", "nudge", "preset"])
def test_no_move_by_hand_while_the_camera_calibrates(action: m.HandAction) -> None:
    control = _control()
    refused = control.take_hand(_hand(action, 100.0), 100.0, calibrating=True)
    assert refused is not None and "calibration mode" in refused and control.held_by == ""
    assert control.take_hand(_hand("hold", 100.0), 100.0, calibrating=True) is None, \
        "holding it moves nothing"


def test_a_position_beyond_the_messages_ranges_is_shown_at_their_edge() -> None:
    assert PtzControl.on_the_wire(181.0, -95.0, 0) == (180.0, -90.0, 1)
    assert PtzControl.on_the_wire(-35.5, 12.0, 500) == (-35.5, 12.0, 500)


def test_a_camera_of_another_picture_starts_on_the_data_sheets_line_in_that_picture() -> None:
    """A 1920 × 1080 camera before its lens is measured: the straight line scaled to its
    picture (the same field of view as the AXIS 215's 704 px wide one), square pixels; a
    measured lens, once a pose brings one, is kept whatever the camera says after."""
    control = _control()
    control.camera_limits(PtzLimits(), (1920, 1080))
    wide = control.lens.intrinsics(1)
    assert (wide.width_px, wide.height_px) == (1920, 1080)
    assert wide.fy_px == pytest.approx(3.8 * 1920 / 3.6) and wide.fz_px == wide.fy_px
    lens = [m.LensAtZoom(zoom=z, focal_px=f, distortion=[0.0] * 5, passpoints=30,
                         mean_error_px=0.4) for z, f in ((1, 1900.0), (9999, 22000.0))]
    assert control.take_pose(_pose().model_copy(update={"lens": lens, "width_px": 1920,
                                                        "height_px": 1080}), 200.0) == "taken"
    control.camera_limits(PtzLimits(), (1920, 1080))
    assert control.lens.focal_px(9999) == 22000.0 and control.lens.width_px == 1920
