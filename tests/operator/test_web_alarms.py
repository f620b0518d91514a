"""The page's alarms and its plot's history (pure): each cause the operator must see, when it
began and when it ended."""

from __future__ import annotations

import pytest

from common import messages as m
from services.web.alarms import Alarm, AlarmBoard, calibration_alarms, crane_alarms, service_alarms
from services.web.state import LiveState


def _crane(t: float = 10.0, **changes: object) -> m.CraneState:
    fields = {"measured_s": t, "status": "tracking", "x_mm": 0.0, "y_mm": 0.0,
              "target_x_mm": 0.0, "target_y_mm": 0.0, "enabled": True, "moving": True,
              "fault_bits": 0, "mode": "armed", "mode_by": "anna", "mode_reason": "run 3"}
    return m.CraneState(**{**fields, **changes})  # type: ignore[arg-type]


def _offload(t: float, error_mm: float, limit: float = 5.0) -> m.GravityOffload:
    share = 100 * error_mm / 2000
    return m.GravityOffload(measured_s=t, horizontal_error_mm=error_mm, cable_length_mm=2000.0,
                            vertical_loss_pct=0.1, horizontal_share_pct=share,
                            warning=share > limit, warn_above_pct=limit)


def _estimate(t: float) -> m.RobotEstimate:
    return m.RobotEstimate(measured_s=t, algorithm="default", valid=True, x_mm=0.0, y_mm=0.0,
                           z_mm=0.0, vx_mm_s=0.0, vy_mm_s=0.0)


def _causes(alarms: list[Alarm]) -> list[str]:
    return [a.cause for a in alarms]


def test_a_crane_that_tracks_within_the_limit_raises_nothing() -> None:
    assert crane_alarms(_crane(), _estimate(9.9), _offload(9.9, 50.0), 10.0) == []


def test_sideways_pull_above_the_limit_names_it_and_the_error() -> None:
    [alarm] = crane_alarms(_crane(), None, _offload(9.9, 150.0), 10.0)
    assert alarm.cause == "sideways pull"
    assert alarm.detail == ("7.5 % of the cable's pull (limit 5 %), the crane 150 mm off the "
                            "robot")
    assert crane_alarms(_crane(), None, _offload(9.9, 150.0, limit=10.0), 10.0) == []
    assert crane_alarms(None, None, _offload(1.0, 150.0), 10.0) == [], "an old figure"


@pytest.mark.parametrize("changes,cause,detail", [
    ({"status": "holding"}, "estimate stale", "the robot's estimate is 2.5 s old"),
    ({"status": "reacquiring"}, "marker lost", "the motion capture's fix"),
    ({"status": "unreachable"}, "crane fault", "does not answer"),
    ({"status": "fault", "fault_bits": 0x12}, "crane fault", "fault register 0x0012"),
    ({"safety_ok": False}, "e-stop", "safety circuit is open"),
    ({"status": "stopped", "mode": "stopped", "mode_reason": "e-stop pressed",
      "mode_by": "gantry"}, "gantry stopped", "e-stop pressed (gantry): reset, then arm"),
])
def test_each_crane_cause(changes: dict, cause: str, detail: str) -> None:
    alarms = crane_alarms(_crane(**changes), _estimate(7.5), None, 10.0)
    assert cause in _causes(alarms)
    assert detail in next(a.detail for a in alarms if a.cause == cause)


def test_a_silent_gantry_is_one_alarm_not_its_last_words() -> None:
    old = _crane(t=1.0, status="holding", safety_ok=False)
    assert crane_alarms(old, None, None, 10.0) == [
        Alarm("crane", "crane silent", "no crane report for 9 s")]


def test_services_gone_or_degraded_and_failed_calibrations() -> None:
    rows = [{"service": "gantry", "instance": "main", "alive": True, "status": "degraded",
             "detail": "crane unreachable"},
            {"service": "tracker", "instance": "main", "alive": False, "status": "ok",
             "detail": ""},
            {"service": "web", "instance": "main", "alive": True, "status": "ok", "detail": ""}]
    assert [(a.cause, a.detail) for a in service_alarms(rows)] == [
        ("service degraded", "gantry/main: crane unreachable"),
        ("service down", "tracker/main is gone")]
    done = m.CollectProgress(measured_s=1.0, camera="ptz1", state="done", passpoints=40,
                             target=40, snapshots=90, skipped={})
    failed = done.model_copy(update={"camera": "ptz2", "state": "failed", "message": "why"})
    assert calibration_alarms({"ptz1": done, "ptz2": failed}) == [
        Alarm("calib:ptz2", "calibration failed", "ptz2: why")]


def test_an_alarm_keeps_its_start_until_it_clears_then_is_listed_as_ended() -> None:
    board = AlarmBoard(keep=2)
    pull = Alarm("offload", "sideways pull", "6 %")
    board.update([pull], 10.0)
    board.update([Alarm("offload", "sideways pull", "8 %")], 11.0)  # worse: the same alarm
    assert board.view()["active"] == [{"cause": "sideways pull", "detail": "8 %",
                                       "since_s": 10.0}]
    board.update([], 12.0)
    assert board.view() == {"active": [], "ended": [
        {"cause": "sideways pull", "detail": "8 %", "since_s": 10.0, "until_s": 12.0}]}
    for t in (13.0, 15.0, 17.0):  # three more come and go: the two latest are kept
        board.update([Alarm("crane", "crane fault", str(t))], t)
        board.update([], t + 1)
    assert [e["detail"] for e in board.view()["ended"]] == ["17.0", "15.0"]


def test_another_cause_on_the_same_subject_is_a_new_alarm() -> None:
    board = AlarmBoard()
    board.update([Alarm("estimate", "marker lost", "")], 1.0)
    board.update([Alarm("estimate", "estimate stale", "")], 2.0)
    assert board.view()["active"][0] == {"cause": "estimate stale", "detail": "",
                                         "since_s": 2.0}
    assert board.view()["ended"][0]["cause"] == "marker lost"


def test_alarms_begin_when_judged_not_when_a_page_first_looks() -> None:
    state = LiveState()
    state.on_message(_crane(t=100.0, safety_ok=False))
    state.judge(100.2)  # the service's timer
    state.on_message(_crane(t=104.0, safety_ok=False))
    assert state.view(104.5)["alarms"]["active"][0]["since_s"] == 100.2


def test_the_plot_keeps_the_largest_of_each_second_for_history_s() -> None:
    state = LiveState(history_s=10.0)
    for i in range(200):  # 20 s at 10 Hz; the error rises by 1 mm a sample
        state.on_message(_offload(1000.0 + i * 0.1, 20.0 + i))
    history = state.view(1020.0)["history"]
    assert history["limit_pct"] == 5.0 and history["step_s"] == 1.0
    points = history["points"]
    assert 10 <= len(points) <= 11, "the last 10 s, a point a second"
    assert points[-1] == [-1.0, 219, pytest.approx(10.95)], "the largest of the last second"
    assert [p[0] for p in points] == sorted(p[0] for p in points)
    assert points[0][0] >= -11.0
    state.on_message(_offload(900.0, 500.0))  # a late old figure changes nothing
    assert state.view(1020.0)["history"]["points"] == points
