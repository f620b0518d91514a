"""The operator in command over the wires, against the sim's Modbus crane controller on real
time (tests/gantry/rig.py): commands and their audit on the bus, a stop over the bus, the
lab's register maps, the command line and the sim's e-stop. The rules of the modes (arming,
stops, latched faults, the cross-check, another Modbus client's setpoints, the standing robot,
the lost robot) run on a simulated clock in test_modes.py."""

from __future__ import annotations

import time

import numpy as np

from common.crane_registers import FAULT_SAFETY
from tests.conftest import wait_for
from tests.gantry.rig import (
    SETTLE_SAMPLE_S,
    CraneRig,
    Operator,
    assert_never_swings_off,
    feeding,
    off_from_the_first_pass,
)

TARGET = np.array([600.0, -300.0])


def _moving(rig: dict) -> None:
    operator: Operator = rig["operator"]
    operator.arm_within(10)
    wait_for(lambda: np.linalg.norm(rig["crane"].state()[1]) > 100.0, timeout=4)


def test_arming_needs_a_fresh_estimate(rig: dict) -> None:
    operator: Operator = rig["operator"]
    before = time.time()
    reply = operator.send("arm")  # no frames at all
    assert not reply.accepted and "no fresh estimate" in reply.detail
    assert reply.mode == "disarmed" and not rig["crane"].state()[2]
    # the audit: the refused command, who sent it and the answer, in the gantry's own state
    audited = wait_for(lambda: next((s for s in reversed(operator.states)
                                     if s.command_s >= before), None), timeout=5)
    assert (audited.command, audited.command_by, audited.command_accepted) == (
        "arm", "operator (as test operator)", False)
    assert "no fresh estimate" in audited.command_detail and audited.mode_by == "gantry"


def test_a_stop_over_the_bus_disables_the_moving_crane_within_a_control_period(
        rig: dict) -> None:
    """The wire's part of the stop (bus → loop → Modbus); what follows a stop (reset, arm) is
    in test_modes.py on a simulated clock."""
    crane: CraneRig = rig["crane"]
    operator: Operator = rig["operator"]
    with feeding(crane, rig["world"], lambda t: TARGET + [80.0 * t, 0.0]):
        _moving(rig)
        sent = time.monotonic()
        reply = operator.send("stop")
        wait_for(lambda: not crane.state()[2], timeout=1)
        assert time.monotonic() - sent < 0.25 + 0.05, "disabled within a control period"
        assert reply.accepted and reply.mode == "stopped"


def test_the_gantry_drives_a_crane_with_the_labs_register_map(rig: dict) -> None:
    crane: CraneRig = rig["crane"]
    with feeding(crane, rig["world"], lambda _t: TARGET):
        _moving(rig)
        wait_for(lambda: np.linalg.norm(crane.state()[0] - TARGET) < 20.0, timeout=8)
        # and its position read back right, once the crane has settled: on the way the loop
        # can overshoot the robot (up to 75 mm for 1–3 s, longer on a busy machine), and the
        # gantry's reading is a control period old; a wrong map reads metres off, never 25 mm
        states = rig["operator"].states

        def settled_and_read_back() -> bool:
            position, velocity, _, _ = crane.state()
            return bool(np.linalg.norm(position - TARGET) < 20.0
                        and np.linalg.norm(velocity) < 30.0
                        and np.hypot(states[-1].x_mm - TARGET[0],
                                     states[-1].y_mm - TARGET[1]) < 25.0)

        wait_for(settled_and_read_back, timeout=15,
                 why=lambda: f"crane at {crane.state()[0]}, read back "
                 + ", ".join(f"({s.x_mm:.0f}, {s.y_mm:.0f}) {s.status} {s.mode} "
                             f"{time.time() - s.measured_s:.2f} s ago" for s in states[-6:]))


def test_a_robot_standing_still_is_not_overshot(rig: dict) -> None:
    """The crane comes from 670 mm away to a robot standing still, and once within 15 mm of it
    (at most a second after its first pass within 20 mm) never swings more than 15 mm off:
    each picture is paired with where the motion capture's marker on the carriage says the
    crane was when it was taken. Adding the newest picture's offset to the controller's
    latest report instead swung it ±35–75 mm for 1–3 s. The live lab's part of issue 47's
    criterion (the same rule on a simulated clock: test_modes.py)."""
    crane: CraneRig = rig["crane"]
    with feeding(crane, rig["world"], lambda _t: TARGET):
        _moving(rig)
        off = off_from_the_first_pass(
            lambda: float(np.linalg.norm(crane.state()[0] - TARGET)),
            lambda: time.sleep(SETTLE_SAMPLE_S),  # pacing: samples every 20 ms
            time.monotonic, time.monotonic() + 20)
    assert_never_swings_off(off)


def test_the_command_line_says_what_the_gantry_made_of_a_command(
        rig: dict, make_bus, capsys) -> None:  # noqa: ANN001
    from services.gantry.command_cli import send

    wait_for(lambda: rig["operator"].states, timeout=10)  # the gantry is up
    assert send(make_bus(), "arm", "night shift", "", 3.0, "operator") == 1, \
        "refused: nothing in view"
    assert "arm: refused — no fresh estimate" in capsys.readouterr().out
    assert send(make_bus(), "stop", "night shift", "coffee", 3.0, "operator") == 0
    assert "stop: done — coffee (gantry stopped)" in capsys.readouterr().out
    state = wait_for(lambda: rig["operator"].states[-1].mode == "stopped"
                     and rig["operator"].states[-1])
    assert state.mode_by == "operator (as night shift)" and state.mode_reason == "coffee"


def test_stb_sim_estop_presses_and_releases_the_sims_e_stop(rig: dict) -> None:
    from services.sim.estop_cli import main as estop

    crane: CraneRig = rig["crane"]
    port = ["--set", f"crane.port={crane.port}"]
    assert estop(port) == 0
    wait_for(lambda: not crane.model.safety_ok and crane.state()[3] & FAULT_SAFETY, timeout=1)
    wait_for(lambda: rig["operator"].states and not rig["operator"].states[-1].safety_ok)
    assert estop([*port, "--release"]) == 0
    wait_for(lambda: crane.model.safety_ok, timeout=1)
    assert crane.state()[3] & FAULT_SAFETY, "latched until a reset"
    assert estop(["--set", "crane.port=1"]) == 3, "nothing listens there"
