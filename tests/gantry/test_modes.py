"""The operator in command, on a simulated clock (tests/gantry/sim_rig.py): the gantry starts
disarmed, moves the crane only once armed, stops within a control period, never clears a
latched fault by itself, stops when the crane stops on its own or disagrees with the motion
capture or another Modbus client writes setpoints, does not overshoot a robot standing still,
and finds a lost robot again by the motion capture. The same rules over the bus and Modbus on
real time: test_modes_service.py."""

from __future__ import annotations

import re

import numpy as np

from common.crane_registers import FAULT_SAFETY, FAULT_WATCHDOG
from tests.gantry.camera import CAMERA, pixel_of
from tests.gantry.rig import (
    GROUND_MM,
    MARKER_MM,
    SETTLE_SAMPLE_S,
    assert_never_swings_off,
    off_from_the_first_pass,
)
from tests.gantry.sim_rig import POLL_S, SimGantry, rig_settings

TARGET = np.array([600.0, -300.0])


def _speed(gantry: SimGantry) -> float:
    return float(np.linalg.norm(gantry.state()[1]))


def _moving(gantry: SimGantry) -> None:
    gantry.arm_when_in_view()
    assert gantry.run(4, lambda: _speed(gantry) > 100.0), "the crane never set off"


def test_it_starts_disarmed_and_moves_the_crane_only_once_armed() -> None:
    gantry = SimGantry(rig_settings(), lambda _t: TARGET)
    start = gantry.state()[0]
    gantry.run(1.5)  # it sees the robot all this while
    position, _, enabled, _ = gantry.state()
    assert gantry.mode == "disarmed" and gantry.status == "idle"
    assert not enabled and np.allclose(position, start), "never enabled, never moved"
    assert gantry.crane.setpoints == 0, "no setpoints while disarmed"
    reply = gantry.send("arm")
    assert reply.decision.accepted and reply.decision.mode == "armed"
    assert gantry.run(8, lambda: np.linalg.norm(gantry.state()[0] - TARGET) < 20.0)
    assert gantry.loop.modes.by == "operator (as test operator)"


def test_stop_acts_within_a_control_period_and_only_reset_and_arm_move_again() -> None:
    gantry = SimGantry(rig_settings(), lambda t: TARGET + [80.0 * t, 0.0])
    _moving(gantry)
    sent = gantry.now
    reply = gantry.send("stop")
    assert gantry.run(1, lambda: not gantry.state()[2])
    assert gantry.now - sent <= 1 / gantry.settings.control_hz + POLL_S, \
        "disabled within a control period"
    assert reply.decision.accepted and reply.decision.mode == "stopped"
    assert gantry.run(3, lambda: _speed(gantry) < 1.0)
    refused = gantry.send("arm")
    assert not refused.decision.accepted and "reset first" in refused.decision.detail
    gantry.run(0.5)
    assert not gantry.state()[2] and gantry.status == "stopped"
    assert gantry.send("reset").decision.mode == "disarmed"
    assert gantry.send("arm").decision.accepted
    assert gantry.run(4, lambda: _speed(gantry) > 50.0)
    assert gantry.send("disarm").decision.mode == "disarmed"
    assert gantry.run(1, lambda: not gantry.state()[2])


def test_a_restarted_gantry_leaves_a_watchdog_stopped_crane_alone_until_reset_and_arm() -> None:
    gantry = SimGantry(rig_settings(), lambda _t: TARGET + [0.0, 400.0])
    _moving(gantry)
    gantry.killed(3.0)  # mid-motion: no heartbeat, no setpoints; then started again
    _, velocity, enabled, faults = gantry.state()
    assert faults & FAULT_WATCHDOG and not enabled and np.linalg.norm(velocity) < 1.0
    gantry.run(1.5)
    _, _, enabled, faults = gantry.state()
    assert not enabled and faults & FAULT_WATCHDOG, "no enable, no reset by itself"
    assert gantry.mode == "disarmed" and gantry.status == "fault"
    refused = gantry.send("arm")
    assert not refused.decision.accepted and "watchdog" in refused.decision.detail
    assert gantry.send("reset").decision.accepted
    assert gantry.run(2, lambda: not gantry.state()[3])
    assert gantry.send("arm").decision.accepted
    assert gantry.run(4, lambda: _speed(gantry) > 50.0)


def test_a_crane_that_disagrees_with_its_marker_stops_the_gantry_and_will_not_arm() -> None:
    """The crane's reported position (through its frame) against the motion capture's marker
    on its carriage: 200 mm apart for longer than the check's window while armed → stopped,
    the crane disabled, nothing written after; then no arming until they agree."""
    slipped_at = [float("inf")]
    gantry = SimGantry(rig_settings(), lambda t: TARGET + [40.0 * t, 0.0],
                       crane_marker=lambda t: np.array([200.0, 0.0]) if t >= slipped_at[0]
                       else np.zeros(2))
    _moving(gantry)
    slipped_at[0] = gantry.now
    assert gantry.run(3, lambda: gantry.mode == "stopped")
    reason = gantry.loop.modes.reason
    off = re.search(r"disagrees with the motion capture by (\d+) mm", reason)
    assert off and 150 <= int(off.group(1)) <= 300, reason  # 200 mm, and motion
    assert "stb gantry commission" in reason
    assert gantry.run(1, lambda: not gantry.state()[2])
    written = gantry.crane.setpoints
    gantry.run(1.0)
    assert gantry.crane.setpoints == written, "no setpoint once stopped"
    assert gantry.send("reset").decision.accepted
    refused = gantry.send("arm")
    assert not refused.decision.accepted and "disagrees" in refused.decision.detail
    slipped_at[0] = float("inf")
    gantry.arm_when_in_view()


def test_it_follows_then_holds_when_frames_stop_or_the_marker_is_lost() -> None:
    target = np.array([350.0, -250.0])
    frames_stop, moves_at = [float("inf")], [float("inf")]

    def robot(t: float) -> np.ndarray | None:  # stands; then drives 2 s and leaves the view
        if t < moves_at[0]:
            return target
        return target + [150.0 * (t - moves_at[0]), 0.0] if t < moves_at[0] + 2 else None

    gantry = SimGantry(rig_settings(), robot, paused=lambda t: frames_stop[0] <= t < moves_at[0])
    gantry.arm_when_in_view()
    assert gantry.run(8, lambda: np.linalg.norm(gantry.state()[0] - target) < 20.0)
    assert gantry.state()[2] and not gantry.setpoints[-1][2]
    assert gantry.run(5, lambda: _speed(gantry) < 1.0)  # settled
    frames_stop[0] = gantry.now
    assert gantry.run(5, lambda: gantry.setpoints[-1][2]), "frames stop: the estimate goes stale"
    held = gantry.state()[0]
    gantry.run(1.0)
    position, velocity, _, _ = gantry.state()
    assert np.linalg.norm(position - held) < 5.0 and np.linalg.norm(velocity) < 1.0
    moves_at[0] = gantry.now
    gantry.run(3.5)
    assert gantry.setpoints[-1][2], "marker out of sight → hold"
    assert all(abs(x) <= 2950 and abs(y) <= 2950 for x, y, _ in gantry.setpoints)


def test_a_crane_disabled_at_the_controller_stops_the_gantry() -> None:
    gantry = SimGantry(rig_settings(), lambda t: TARGET + [60.0 * t, 0.0])
    _moving(gantry)
    gantry.model.write_control(gantry.now, 0)  # someone disables it at the controller
    assert gantry.run(1, lambda: gantry.mode == "stopped")
    assert gantry.loop.modes.reason == "crane disabled at the controller"
    gantry.run(1.5)
    assert not gantry.state()[2], "the gantry does not enable it again"


def test_another_clients_setpoints_stop_the_gantry() -> None:
    """Modbus has no authentication: setpoints written beside the gantry's (a commissioning
    tool left running, a second gantry) become the crane's target; the gantry sees them in
    the setpoint registers it reads back at every poll and stops the crane, naming why."""
    gantry = SimGantry(rig_settings(), lambda t: TARGET + [60.0 * t, 0.0])
    _moving(gantry)
    gantry.run(1.0)
    assert str(gantry.mode) == "armed", "its own setpoints are no reason to stop"
    began = gantry.now
    while gantry.mode != "stopped" and gantry.now - began < 3:
        gantry.crane.foreign_setpoint(-2500.0, 2500.0)  # ten times a second
        gantry.run(0.1, lambda: gantry.mode == "stopped")
    print(f"stopped {gantry.now - began:.2f} s after the first foreign write")
    assert gantry.mode == "stopped" and gantry.now - began < 0.2
    assert "another Modbus client writes setpoints" in gantry.loop.modes.reason
    assert gantry.run(1, lambda: not gantry.state()[2])
    assert gantry.state()[0][0] > -2000.0, "stopped on its way, long before the foreign setpoint"


def test_an_e_stop_stops_the_gantry_at_once_and_holds_until_released_and_reset() -> None:
    gantry = SimGantry(rig_settings(), lambda t: TARGET + [60.0 * t, 0.0])
    _moving(gantry)
    gantry.model.set_safety_circuit(gantry.now, closed=False)
    assert gantry.run(0.5, lambda: gantry.mode == "stopped")
    assert "e-stop" in gantry.loop.modes.reason and gantry.state()[3] & FAULT_SAFETY
    gantry.send("reset")  # while it is still pressed: the circuit stays open
    refused = gantry.send("arm")
    assert not refused.decision.accepted and "safety circuit open" in refused.decision.detail
    gantry.model.set_safety_circuit(gantry.now, closed=True)
    assert gantry.send("reset").decision.accepted
    assert gantry.run(2, lambda: not gantry.state()[3])
    assert gantry.send("arm").decision.accepted
    assert gantry.run(4, lambda: _speed(gantry) > 50.0)


def test_a_robot_standing_still_is_not_overshot() -> None:
    """The crane comes from 670 mm away to a robot standing still, and once within 15 mm of it
    (at most a second after its first pass within 20 mm) never swings more than 15 mm off:
    each picture is paired with where the motion capture's marker on the carriage says the
    crane was when it was taken. Adding the newest picture's offset to the controller's
    latest report instead swung it ±35–75 mm for 1–3 s."""
    gantry = SimGantry(rig_settings(), lambda _t: TARGET)
    _moving(gantry)
    off = off_from_the_first_pass(lambda: float(np.linalg.norm(gantry.state()[0] - TARGET)),
                                  lambda: gantry.run(SETTLE_SAMPLE_S), lambda: gantry.now, 20.0)
    assert_never_swings_off(off)


def test_the_robot_is_found_again_from_the_motion_capture_after_it_left_the_view() -> None:
    """Frames and mocap stop for 4.5 s (as in a bus outage) half a second after the robot set
    off; it drives on at 290 mm/s, out of the tracking camera's view (±1 m); when they are back
    the gantry goes to the motion capture's fix at its reduced speed until the marker is in
    view, then tracks."""
    start = np.array([-700.0, 0.0])

    def robot(t: float) -> np.ndarray:  # stands 2 s, drives 5 s at 290 mm/s, then 50 mm/s
        return start + [290.0 * min(max(t - 2.0, 0.0), 5.0) + 50.0 * max(t - 7.0, 0.0), 0.0]

    gantry = SimGantry(rig_settings(), robot, mocap=True, paused=lambda t: 2.5 <= t < 7.0)
    gantry.arm_when_in_view(2)
    gantry.run(6.8 - gantry.now)  # into the outage's end
    held = gantry.state()
    assert np.linalg.norm(held[1]) < 1.0, "it holds through the outage"
    u, _v, _r = pixel_of(np.array([*robot(6.8), GROUND_MM + MARKER_MM]), held[0])
    assert not 0 <= u < CAMERA.width_px, "the robot is out of view"
    assert gantry.run(3, lambda: _speed(gantry) > 50.0)  # reacquiring
    assert _speed(gantry) <= gantry.settings.reacquire_speed_mm_s + 5
    assert gantry.run(1, lambda: gantry.status == "reacquiring")
    assert gantry.run(20, lambda: np.linalg.norm(gantry.state()[0] - robot(gantry.now)) < 60.0)
    assert gantry.mode == "armed"


def test_arming_with_the_robot_out_of_view_goes_by_the_motion_capture() -> None:
    robot = np.array([1400.0, 300.0])  # 1.4 m away: not in the tracking camera's view
    gantry = SimGantry(rig_settings(reacquire_speed_mm_s=400.0), lambda _t: robot, mocap=True)
    gantry.arm_when_in_view()  # the motion capture alone is enough to arm
    assert gantry.run(15, lambda: np.linalg.norm(gantry.state()[0] - robot) < 30.0)
