"""The calib service's pose rules on their own (pure, the time given)."""

from __future__ import annotations

from typing import Any

from common import messages as m
from services.calib.pose_rules import (
    ForeignPoses,
    health,
    next_version,
    rotation_gap_deg,
    same_solve,
)

SOLVED: dict[str, Any] = dict(
    measured_s=100.0, camera="ptz1", x_mm=3550.0, y_mm=1090.0, z_mm=2190.0, rx_deg=180.0,
    ry_deg=30.0, rz_deg=165.0, focal_px=743.1, mean_error_px=1.2, passpoints=100)


def test_a_solve_is_one_version_above_the_held_pose() -> None:
    solve = m.CameraPose(**SOLVED)
    assert next_version(solve, None).version == 1
    held = m.CameraPose(**SOLVED, version=2**53 - 1)
    assert next_version(solve, held).version == 2**53
    assert next_version(solve, held).rz_deg == 165.0, "only the version changes"


def test_its_own_pose_again_is_the_same_solve_at_any_version_or_sending_time() -> None:
    own = m.CameraPose(**SOLVED, version=3)
    echo = own.model_copy(update={"version": 9, "sent_s": 1234.0})
    assert same_solve(echo, own)
    moved = own.model_copy(update={"rz_deg": 100.0})
    assert not same_solve(moved, own)
    assert rotation_gap_deg(moved, own) == 65.0
    across = own.model_copy(update={"rx_deg": -179.0})
    assert rotation_gap_deg(across, own) == 1.0, "angles compared across ±180°"


def test_foreign_poses_count_for_their_window_and_say_when_the_count_changes() -> None:
    foreign = ForeignPoses(window_s=60.0)
    assert foreign.next_change_s() is None and foreign.counts(0.0) == {}
    assert foreign.heard("ptz1", 10.0), "the first one is worth a log line"
    assert not foreign.heard("ptz1", 20.0)
    assert foreign.heard("ptz2", 30.0)
    assert foreign.counts(30.0) == {"ptz1": 2, "ptz2": 1}
    assert foreign.next_change_s() == 70.0
    assert foreign.counts(70.0) == {"ptz1": 1, "ptz2": 1}, "the one heard at 10 s is gone"
    assert foreign.next_change_s() == 80.0
    assert foreign.counts(90.0) == {}
    assert foreign.heard("ptz1", 200.0), "first again after a quiet window"


def test_health_names_cameras_without_a_pose_and_foreign_poses() -> None:
    pose = m.CameraPose(**SOLVED)
    assert health(["ptz1"], {"ptz1": pose}, {}) == ("ok", "")
    status, detail = health(["ptz1", "ptz2"], {"ptz1": pose}, {"ptz1": 3})
    assert status == "degraded"
    assert detail.startswith("no pose yet: ptz2; ptz1: 3 poses it did not send")
