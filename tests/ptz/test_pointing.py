"""The pointing check (pure): the angle from where the pose puts the robot marker to the
nearest marker found, and a problem only after disagreeing previews in a row."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from common import messages as m
from common.ptz_lens import axis_215
from services.ptz.pointing import NOT_SEEN, InfraredSchedule, PointingCheck, pointing_error_deg

INTR = axis_215(3.8)


def _marker(u: float, v: float) -> m.DetectedMarker:
    return m.DetectedMarker(u_px=u, v_px=v, radius_long_px=3, radius_short_px=3, angle_deg=0,
                            roundness=1.0, area_px=28)


def _preview(robot_px: list[float] | None, *markers: tuple[float, float]) -> m.PtzPreview:
    return m.PtzPreview(measured_s=time.time(), camera="ptz1", seq=1, width_px=704,
                        height_px=576, jpeg=b"", pan_deg=0, tilt_deg=0,
                        markers=[_marker(u, v) for u, v in markers], robot_px=robot_px)


def test_the_error_is_the_angle_to_the_nearest_marker() -> None:
    centre = [INTR.cy_px, INTR.cz_px]
    # one degree to the side of the optical axis: fy · tan(1°) pixels
    one_degree = INTR.cy_px + INTR.fy_px * math.tan(math.radians(1.0))
    error = pointing_error_deg(_preview(centre, (one_degree, INTR.cz_px), (10, 10)), INTR)
    assert error == pytest.approx(1.0, abs=1e-6)


def test_nothing_to_judge_without_a_robot_pixel_or_with_the_robot_outside_the_picture() -> None:
    assert pointing_error_deg(_preview(None, (300, 300)), INTR) is None
    assert pointing_error_deg(_preview([-5.0, 300.0], (300, 300)), INTR) is None
    assert pointing_error_deg(_preview([300.0, 600.0], (300, 300)), INTR) is None
    assert pointing_error_deg(_preview([300.0, 300.0]), INTR) == NOT_SEEN


def test_a_problem_only_after_disagreeing_previews_in_a_row() -> None:
    check = PointingCheck(tolerance_deg=3.0, persist=3)
    far, near = _preview([352.0, 288.0], (600, 100)), _preview([352.0, 288.0], (353, 289))
    for preview in (far, far, near, far, far):  # one agreeing preview resets the count
        check.observe(preview, INTR, infrared=False)
        assert check.problem() is None
    check.observe(_preview(None), INTR, infrared=True)  # nothing to judge
    check.observe(_preview([352.0, 288.0]), INTR, infrared=False)  # markers dim: no proof
    assert check.problem() is None
    check.observe(far, INTR, infrared=False)
    assert "seen 2" in (check.problem() or "")
    check.observe(_preview([352.0, 288.0]), INTR, infrared=True)
    assert "not seen" in (check.problem() or "")
    check.forget()
    assert check.problem() is None and check.error_deg is None


def test_while_infrared_previews_are_taken_daylight_ones_are_not_judged() -> None:
    """In daylight the spots found are reflections: three in a row far from the robot
    (previews at 2 Hz, an infrared one every 2 s) made a problem of a camera pointing right."""
    check = PointingCheck(tolerance_deg=3.0, persist=2, daylight=False)
    reflection = _preview([352.0, 288.0], (600, 100))
    for _ in range(3):
        check.observe(reflection, INTR, infrared=False)
    assert check.problem() is None and check.error_deg is None
    check.observe(_preview([352.0, 288.0], (353, 289)), INTR, infrared=True)
    assert check.error_deg == pytest.approx(0.1, abs=0.1) and check.problem() is None
    for _ in range(2):
        check.observe(reflection, INTR, infrared=True)  # infrared: the robot's marker
    assert check.problem() is not None


def test_a_marker_too_small_to_be_found_is_not_judged() -> None:
    """Far off at the widest zoom the robot's 19 mm marker is about 1.3 px in radius, and the
    detector's filters (area ≥ 3 px, roundness < 1.21) miss most of those: such a preview says
    nothing about the pose (in the demo they made 'wrong pose?' problems every lap)."""
    far = _preview([300.0, 300.0]).model_copy(update={"robot_radius_px": 1.3})
    near = _preview([300.0, 300.0]).model_copy(update={"robot_radius_px": 2.0})
    assert pointing_error_deg(far, INTR, min_radius_px=1.4) is None
    assert pointing_error_deg(near, INTR, min_radius_px=1.4) == NOT_SEEN
    check = PointingCheck(tolerance_deg=3.0, persist=2, min_radius_px=1.4)
    for _ in range(5):
        check.observe(far, INTR, infrared=True)
    assert check.problem() is None and check.error_deg is None
    for _ in range(2):
        check.observe(near, INTR, infrared=True)
    assert "not seen" in (check.problem() or "")


def test_the_filter_switches_only_when_a_check_is_due() -> None:
    """A mechanical switch: at once the first time, then every ``every_s``; every
    ``confirm_s`` while the latest judged preview disagreed; never while a recording runs
    unless asked; at once again after ``again`` (a new pose, the camera back)."""
    schedule = InfraredSchedule(every_s=300.0, confirm_s=2.0)
    assert schedule.due(0.0, doubting=False, recording=False)
    schedule.taken(0.0)
    schedule.judged()
    assert not schedule.due(299.0, doubting=False, recording=False)
    assert schedule.due(300.0, doubting=False, recording=False)
    assert not schedule.due(1.9, doubting=True, recording=False)
    assert schedule.due(2.0, doubting=True, recording=False)
    assert not schedule.due(1000.0, doubting=True, recording=True), "a recording runs"
    schedule.again()
    assert schedule.due(0.5, doubting=False, recording=False)
    assert not schedule.due(0.5, doubting=False, recording=True)
    asked = InfraredSchedule(every_s=300.0, confirm_s=2.0, while_recording=True)
    assert asked.due(0.0, doubting=False, recording=True)
    never = InfraredSchedule(every_s=0.0, confirm_s=2.0)
    assert not never.due(1e9, doubting=True, recording=False)
    brief = InfraredSchedule(every_s=0.7, confirm_s=2.0)
    brief.taken(0.0)
    brief.judged()
    assert brief.due(0.7, doubting=True, recording=False), "never later than every_s"


def test_doubting_is_a_disagreement_on_the_way_to_a_problem() -> None:
    check = PointingCheck(tolerance_deg=3.0, persist=2, daylight=False)
    assert not check.doubting()
    check.observe(_preview([352.0, 288.0], (500, 500)), INTR, infrared=True)
    assert check.doubting() and check.problem() is None
    check.observe(_preview([352.0, 288.0], (353, 289)), INTR, infrared=True)
    assert not check.doubting()


def test_an_infrared_preview_that_judged_nothing_is_tried_again_ever_later() -> None:
    """The robot out of the picture or too small in it: again after confirm_s, then 2×, 4×…
    up to every_s, so that a robot long out of view does not switch the filter every 2 s."""
    schedule = InfraredSchedule(every_s=60.0, confirm_s=2.0)
    now, waits = 0.0, []
    schedule.taken(now)
    for _ in range(7):
        wait = next(w for w in np.arange(0.5, 61.0, 0.5)
                    if schedule.due(now + w, doubting=False, recording=False))
        waits.append(float(wait))
        now += wait
        schedule.taken(now)
    assert waits == [2.0, 4.0, 8.0, 16.0, 32.0, 60.0, 60.0]
    schedule.judged()
    assert not schedule.due(now + 59.5, doubting=False, recording=False)
    assert schedule.due(now + 2.0, doubting=True, recording=False)
