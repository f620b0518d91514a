"""The PTZ service's rules on a simulated clock (``tests/ptz/sim_rig.py``): no move without a
pose, the calibration mode's hold and lease, a pose from the future, the pointing check and
its infrared previews, a recording that keeps the filter still, someone else's move, a
reboot, an operator's hand, a flood of calibration requests. The wires (HTTP, the bus) are
``test_service.py``'s."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from common import keys
from common import messages as m
from common.bus import Bus
from common.camera import head_pose, project
from common.ptz_lens import axis_215, axis_215_px
from services.ptz.aim import aim_error_deg
from services.ptz.camera import AxisPtzCamera
from services.ptz.service import watch_recordings
from services.sim.ptz import PtzHead
from tests.conftest import wait_for
from tests.ptz.sim_rig import MOUNT, TARGET, SimPtz

HELD = (-4.0, 3.0)


def following(rig: SimPtz, within_deg: float = 0.5) -> Callable[[], bool]:
    def check() -> bool:
        return bool(rig.states) and rig.states[-1].status == "tracking" and \
            rig.states[-1].aim_error_deg < within_deg
    return check


def true_aim_error(rig: SimPtz) -> float:
    last = rig.states[-1]
    return aim_error_deg(rig.target, MOUNT, last.pan_deg, last.tilt_deg)


def test_no_move_without_a_pose_then_it_follows() -> None:
    rig = SimPtz()
    rig.run(0.5)  # ten robot samples
    assert rig.states[-1].status == "waiting_for_pose"
    assert rig.camera.head.state(rig.clock())[:2] == (0.0, 0.0), "no move without a pose"
    rig.solve()
    rig.until(following(rig), 1.0)
    assert true_aim_error(rig) < 0.5
    assert rig.states[-1].zoom == 1 and rig.states[-1].focal_px == pytest.approx(axis_215_px(3.8))


def test_calibration_mode_holds_still_detects_and_ends_with_its_lease() -> None:
    rig = SimPtz()
    detections: list[m.MarkerDetections] = rig.of(keys.PTZ_DETECTIONS)
    snapshots: list[m.CameraFrame] = rig.of(keys.PTZ_SNAPSHOT)

    def renew() -> None:  # as a collector does
        rig.calibration(pan_deg=HELD[0], tilt_deg=HELD[1], zoom=1, lease_s=1.0)

    rig.run(0.2)
    for _ in range(30):
        renew()
        rig.run(0.3)
        detections, snapshots = rig.of(keys.PTZ_DETECTIONS), rig.of(keys.PTZ_SNAPSHOT)
        if len(detections) >= 5:
            break
    assert len(detections) >= 5
    assert rig.camera.head.ir_cut_filter == "off"
    rig.hand("move", pan_deg=60.0, tilt_deg=-20.0)
    rig.hand("nudge", pan_deg=5.0)
    rig.hand("preset", preset="Home")
    seen = len(rig.states)
    for _ in range(5):  # a window: the page's moves must not happen
        renew()
        rig.run(0.3)
    during = rig.states[seen:]
    assert len(during) >= 10 and all(
        abs(s.pan_deg - HELD[0]) < 0.1 and abs(s.tilt_deg - HELD[1]) < 0.1 for s in during), \
        [(s.pan_deg, s.tilt_deg) for s in during]
    assert {s.status for s in during} == {"calibrating"}
    expected = project(TARGET[None, :], head_pose(MOUNT, *HELD), axis_215(3.8))[0]
    detections = rig.of(keys.PTZ_DETECTIONS)
    for d in detections:  # none from before the camera stood where it was held
        (marker,) = d.markers
        assert abs(marker.u_px - expected[0]) < 1.0 and abs(marker.v_px - expected[1]) < 1.0
    snapshots = rig.of(keys.PTZ_SNAPSHOT)
    assert {d.measured_s for d in detections} <= {s.measured_s for s in snapshots}
    assert snapshots[-1].encoding == "jpeg" and snapshots[-1].data[:2] == b"\xff\xd8"
    rig.until(lambda: rig.states[-1].status == "waiting_for_pose", 1.5)  # the lease ran out
    assert rig.camera.head.ir_cut_filter == "auto"
    count = len(rig.of(keys.PTZ_DETECTIONS))
    rig.run(2.0)
    assert len(rig.of(keys.PTZ_DETECTIONS)) == count, "no more once the mode has ended"


def test_a_pose_from_the_future_is_refused_and_cannot_mis_aim_the_camera() -> None:
    """One pose with a wrong rotation stamped in the year 2096 used to win for good: ptz1's
    true aim error went from 0.1° to 60° until a restart, while it reported 'tracking'. Even
    from the calibration service's own answer it is refused."""
    rig = SimPtz()
    rig.solve()
    rig.until(following(rig), 1.0)
    rig.solve(measured_s=4e9, ry_deg=MOUNT.ry_deg - 40.0, rz_deg=MOUNT.rz_deg + 50.0)
    rig.run(1.0)
    assert ("stb/calib/ptz1/pose", "from_future") in rig.bus.dropped
    assert true_aim_error(rig) < 0.5 and rig.states[-1].status == "tracking"


def test_a_wrong_pose_is_caught_by_the_pointing_check() -> None:
    """A pose with a wrong rotation (as a poisoned pose message would bring) points the
    camera away from the robot while its own aim error stays small; the infrared previews
    show it: one at once for the new pose, then one every ``pointing_confirm_s`` (0.7 s
    here) while they disagree — though the check's own period is the default 5 minutes, so
    the filter moves only for these."""
    rig = SimPtz(preview_hz=5.0, pointing_confirm_s=0.7)
    assert rig.settings.pointing_infrared_s == 300.0
    rig.solve()
    rig.until(lambda: rig.states[-1].pointing_error_deg is not None
              and rig.states[-1].pointing_error_deg < 1.0, 3.0)
    assert rig.states[-1].pointing_problem == "" and rig.node.health().status == "ok"
    poisoned_at = rig.now
    rig.solve(rz_deg=MOUNT.rz_deg + 40, mean_error_px=0.2)  # a wrong solve
    rig.until(lambda: rig.states[-1].pointing_problem.startswith("pointing:"), 5.0)
    print(f"wrong pose reported after {rig.now - poisoned_at:.1f} s: "
          f"{rig.states[-1].pointing_problem}")
    assert rig.states[-1].aim_error_deg < 1.0, "the pose's own aim error cannot see it"
    assert true_aim_error(rig) > 10.0
    health = rig.node.health()
    assert health.status == "degraded" and health.detail.startswith("pointing:")
    assert "the pose asked of calib again" in health.detail
    rig.solve(news=False)  # put right at the source: the PTZ service asks again every few
    # seconds while its pictures disagree, and takes it
    rig.until(lambda: rig.states[-1].pointing_problem == "", 8.0)
    assert rig.node.health().status == "ok"
    head = rig.camera.head
    changed = [rig.now, head.ir_cut_moves]  # the right pose's own check done: no move for 2 s

    def settled() -> bool:
        if head.ir_cut_moves != changed[1]:
            changed[:] = [rig.now, head.ir_cut_moves]
        return rig.now - changed[0] >= 2.0

    rig.until(settled, 10.0)
    moves = head.ir_cut_moves
    assert true_aim_error(rig) < 0.5 and rig.states[-1].pointing_problem == ""
    print(f"the filter moved {moves} times")
    assert 2 * 4 <= moves <= 2 * 12, f"the filter moved {moves} times"  # out and in, each
    rig.run(10.0)  # agreeing now: the next check is minutes away
    assert head.ir_cut_moves == moves


def test_the_filter_is_left_alone_while_a_recording_runs(make_bus: Callable[..., Bus]) -> None:
    """A recording's liveliness token (``stb record`` holds one), seen as the service sees it:
    a new pose is not checked in infrared while it is there; once it goes, the check comes at
    the next preview."""
    rig = SimPtz(preview_hz=5.0)
    bus, recorder = make_bus(), make_bus()
    watching = watch_recordings(bus, rig.loop)
    token = recorder.session.liveliness().declare_token(
        keys.recording_key(recorder.prefix, "host-1234"))
    wait_for(lambda: rig.loop.recordings, timeout=5)
    rig.solve()
    rig.until(following(rig), 1.0)
    rig.run(20.0)  # 100 previews
    assert rig.camera.head.ir_cut_moves == 0, "switched while recording"
    token.undeclare()
    wait_for(lambda: not rig.loop.recordings, timeout=5)
    rig.until(lambda: rig.camera.head.ir_cut_moves >= 2, 0.5)
    watching.undeclare()


def test_a_move_by_someone_else_pauses_following_then_it_follows_again() -> None:
    """Frigate's manual override: the camera moved by another client is left alone for
    ``manual_pause_s`` (status manual), then the service takes it back to the robot."""
    rig = SimPtz(manual_pause_s=2.0)
    rig.solve()
    rig.until(following(rig), 1.0)
    rig.run(1.0)
    someone = AxisPtzCamera(rig.client(), "ptz1")  # another VAPIX client, the camera's page
    someone.nudge(30.0, -10.0)
    moved_at = rig.now
    rig.until(lambda: rig.states[-1].status == "manual", 1.0)
    seen = len(rig.states)
    rig.run(moved_at + 1.5 - rig.now)  # the robot's samples keep coming: left alone
    during = rig.states[seen:]
    assert len(during) >= 5 and all(s.aim_error_deg > 10 for s in during), "left where put"
    assert {s.status for s in during} == {"manual"}
    rig.until(following(rig), 2.0)
    assert rig.now - moved_at >= 2.0, "the pause lasted"


def test_a_camera_that_reboots_is_not_taken_for_a_hand() -> None:
    """The camera goes away and comes back at its home position (a reboot), 26° off where it
    looked: not "manual" (it once paused following for 30 s, 11–15° off), it follows again at
    once."""
    far_side = np.array([0.0, -2500.0, 0.0])
    assert aim_error_deg(far_side, MOUNT, 0.0, 0.0) > 20.0
    rig = SimPtz(lambda _t: far_side)
    rig.solve()
    rig.until(following(rig), 1.5)
    rig.run(1.5)  # the first move (from home) counts as ours for 1 s more
    there = far_side + [300.0, 0.0, 0.0]  # a step on: our path spans no more of home
    rig.robot = lambda _t: there
    rig.until(following(rig), 1.0)
    rig.transport.up = False
    rig.until(lambda: rig.states[-1].status == "camera_unreachable", 1.0)
    rebooted = len(rig.states)
    rig.run(2.0)
    rig.camera.head = PtzHead(MOUNT, latency_s=0.05)  # back, at home
    rig.transport.up = True
    rig.until(following(rig), 10.0, lambda: str({s.status for s in rig.states[rebooted:]}))
    assert "manual" not in {s.status for s in rig.states[rebooted:]}


def test_an_operators_hand_holds_moves_and_releases_the_camera() -> None:
    """From the page (stb/ptz/{camera}/hand): held, the camera follows no more and its own
    moves are not someone else's; moved by hand and to a preset; released, it follows."""
    rig = SimPtz()
    rig.solve()
    rig.until(following(rig), 1.0)
    assert "Home" in rig.states[-1].presets, "the camera's own presets"
    rig.hand("hold")
    rig.until(lambda: rig.states[-1].status == "held", 0.5)
    assert rig.states[-1].held_by == "olga (web h)"

    def at(pan: float, tilt: float) -> Callable[[], bool]:
        return lambda: (abs(rig.states[-1].pan_deg - pan) < 0.5
                        and abs(rig.states[-1].tilt_deg - tilt) < 0.5)

    rig.hand("move", pan_deg=-150.0, tilt_deg=-20.0, zoom=2000)
    rig.until(at(-150.0, -20.0), 3.0)  # the robot's samples keep coming: it stays held
    assert rig.states[-1].status == "held", "its own move is no one else's hand"
    rig.hand("nudge", pan_deg=-5.0, tilt_deg=5.0)
    rig.until(at(-155.0, -15.0), 1.0)
    rig.hand("preset", preset="Home")
    rig.until(at(0.0, 0.0), 3.0)
    rig.run(1.0)
    assert rig.states[-1].status == "held"
    rig.hand("follow")
    rig.until(following(rig), 3.0)
    assert rig.states[-1].held_by == ""


@pytest.mark.parametrize("seed", [5, 6])
def test_a_flood_of_calibration_requests_never_makes_its_own_moves_someone_elses(
        seed: int) -> None:
    """3,000 valid calibration-mode requests in three seconds (on and off, random holds,
    short leases), each taken: the service's own calibration moves, queued in the camera,
    are never taken for someone else's hand; once the flood ends the camera follows the
    robot again."""
    rig = SimPtz(latency_s=PtzHead.latency_s, state_hz=5.0)  # the sim's own latency
    rig.solve()
    rig.until(following(rig, 1.0), 2.0)
    rng = np.random.default_rng(seed)
    flood_start = len(rig.states)
    for i in range(3000):
        rig.calibration(active=bool(i % 7), pan_deg=float(rng.uniform(-180, 180)),
                        tilt_deg=float(rng.uniform(-90, 0)), zoom=int(rng.integers(1, 9999)),
                        lease_s=3.0)
        rig.run(0.001)
    rig.until(following(rig, 1.0), 10.0, lambda: f"last state {rig.states[-1].status}, "
              f"{rig.states[-1].aim_error_deg:.1f}°")
    statuses = {s.status for s in rig.states[flood_start:]}
    assert "calibrating" in statuses and "manual" not in statuses, statuses
