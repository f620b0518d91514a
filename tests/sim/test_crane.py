"""The crane: its controller's behaviour on simulated time, and its Modbus/TCP wire."""

from __future__ import annotations

import asyncio
import threading
import time

import numpy as np
import pytest
from pymodbus.client import AsyncModbusTcpClient

from common import crane_registers as regs
from services.sim.crane import (
    CONTROL_ENABLE,
    CONTROL_RESET,
    ENABLED,
    FAULT_CLAMPED,
    FAULT_WATCHDOG,
    CraneModel,
    CraneParams,
)
from services.sim.crane_server import CraneServer
from tests.conftest import free_port


def _enabled(params: CraneParams | None = None) -> CraneModel:
    crane = CraneModel(params or CraneParams())
    crane.write_control(0.0, CONTROL_ENABLE)
    return crane


def _keep_alive(crane: CraneModel, until: float, period: float = 0.1,
                setpoint: tuple[float, float] | None = None) -> list[tuple[float, np.ndarray]]:
    """Heartbeat (and optionally a setpoint) every ``period`` s; returns the track."""
    track = []
    t = crane.time
    beat = crane.heartbeat
    while t < until:
        t += period
        beat += 1
        if setpoint is not None:
            crane.write_setpoint(t, *setpoint)
        crane.write_heartbeat(t, beat)
        track.append((t, crane.position.copy()))
    return track


def test_reacts_about_half_a_second_after_a_setpoint() -> None:
    crane = _enabled()
    crane.write_setpoint(0.01, 1000.0, 0.0)
    track = _keep_alive(crane, 3.0, period=0.01)
    started = next(t for t, p in track if p[0] > 0.5)
    assert 0.5 <= started <= 0.5 + 0.25 + 0.05, "reaction time + at most one 4 Hz cycle"


def test_speed_and_acceleration_limits_and_arrival() -> None:
    params = CraneParams(max_speed_mm_s=400, max_accel_mm_s2=500)
    crane = _enabled(params)
    crane.write_setpoint(0.0, 2500.0, -1500.0)
    track = _keep_alive(crane, 12.0, period=0.01)
    positions = np.array([p for _, p in track])
    velocity = np.diff(positions, axis=0) / 0.01
    accel = np.diff(velocity, axis=0) / 0.01
    assert np.abs(velocity).max() <= 400 + 1e-6
    assert np.abs(accel).max() <= 500 + 1e-6
    np.testing.assert_allclose(positions[-1], [2500.0, -1500.0], atol=1.0)


def test_setpoints_are_taken_at_most_at_4_hz() -> None:
    crane = _enabled()
    _keep_alive(crane, 5.0, period=0.02, setpoint=(100.0, 100.0))
    assert 19 <= crane.setpoints_taken <= 21


def test_setpoint_outside_the_workspace_is_clamped_and_flagged() -> None:
    crane = _enabled(CraneParams(x_max_mm=1000.0))
    _keep_alive(crane, 8.0, period=0.05, setpoint=(5000.0, 0.0))
    assert crane.faults & FAULT_CLAMPED
    assert crane.position[0] == pytest.approx(1000.0, abs=1.0)
    assert crane.position[0] <= 1000.0


def test_a_placed_crane_reports_its_place_before_its_first_cycle() -> None:
    crane = CraneModel(CraneParams(x_max_mm=1000.0))
    crane.place(5000.0, -300.0)
    assert crane.position.tolist() == [1000.0, -300.0]  # inside its travel
    assert crane.reported.tolist() == [1000.0, -300.0]  # not (0, 0) until the first cycle
    assert crane.velocity.tolist() == [0.0, 0.0]


def test_watchdog_stops_the_crane_and_latches_until_reset() -> None:
    crane = _enabled(CraneParams(max_speed_mm_s=500, max_accel_mm_s2=1000, watchdog_s=0.5))
    track = _keep_alive(crane, 3.0, period=0.1, setpoint=(2500.0, 0.0))
    assert np.abs(crane.velocity).max() > 400, "moving at speed when the sender goes silent"
    silent_at = track[-1][0]
    crane.advance_to(silent_at + 0.5 + 0.01)
    assert not crane.status() & ENABLED and crane.faults & FAULT_WATCHDOG
    crane.advance_to(silent_at + 1.2)
    assert np.all(crane.velocity == 0.0), "braked to a stop (500 mm/s at 1000 mm/s²: 0.5 s)"
    stopped = crane.position.copy()
    crane.write_setpoint(silent_at + 1.3, -2000.0, 0.0)
    crane.write_control(silent_at + 1.3, CONTROL_ENABLE)
    crane.advance_to(silent_at + 2.5)
    np.testing.assert_array_equal(crane.position, stopped)  # no enable while faulted
    crane.write_control(silent_at + 2.5, CONTROL_RESET | CONTROL_ENABLE)
    _keep_alive(crane, silent_at + 4.0, setpoint=(-2000.0, 0.0))
    assert crane.position[0] < stopped[0], "moves again after reset + enable"


def test_heartbeat_alone_keeps_the_watchdog_quiet() -> None:
    crane = _enabled()
    _keep_alive(crane, 5.0, period=0.2)
    assert crane.status() & ENABLED and not crane.faults


def test_modbus_client_drives_the_crane_over_tcp() -> None:
    port = free_port()
    t0 = time.monotonic()

    def clock() -> float:
        return time.monotonic() - t0

    crane = CraneModel(CraneParams(watchdog_s=0.5, x_max_mm=3000.0, max_accel_mm_s2=600.0))
    server = CraneServer(crane, clock, threading.Lock(), "127.0.0.1", port)

    async def main() -> dict:
        serving = asyncio.create_task(server.serve())
        await asyncio.sleep(0.2)
        client = AsyncModbusTcpClient("127.0.0.1", port=port, timeout=2)
        await client.connect()
        try:
            await client.write_register(regs.HR_CONTROL, CONTROL_ENABLE)
            await client.write_registers(regs.HR_SETPOINT_X, regs.int32_to_registers(800)
                                         + regs.int32_to_registers(-300))
            await asyncio.sleep(0.3)
            early = (await client.read_input_registers(0, count=regs.IR_COUNT)).registers
            for beat in range(1, 16):
                await asyncio.sleep(0.1)
                await client.write_register(regs.HR_HEARTBEAT, beat)
            moving = (await client.read_input_registers(0, count=regs.IR_COUNT)).registers
            await client.write_registers(regs.HR_SETPOINT_X, regs.int32_to_registers(9000)
                                         + regs.int32_to_registers(0))
            await asyncio.sleep(0.3)
            clamped = (await client.read_input_registers(0, count=regs.IR_COUNT)).registers
            await asyncio.sleep(1.0)  # silence: the watchdog trips
            silent = (await client.read_input_registers(0, count=regs.IR_COUNT)).registers
            bad = await client.read_input_registers(100, count=2)
            return {"early": early, "moving": moving, "clamped": clamped, "silent": silent,
                    "bad": bad}
        finally:
            client.close()
            await server.close()
            serving.cancel()

    result = asyncio.run(main())
    early, moving, silent = result["early"], result["moving"], result["silent"]
    assert early[regs.IR_ACTUAL_X: regs.IR_ACTUAL_X + 4] == [0, 0, 0, 0], "0.5 s reaction"
    x = regs.registers_to_int32(moving[regs.IR_ACTUAL_X], moving[regs.IR_ACTUAL_X + 1])
    y = regs.registers_to_int32(moving[regs.IR_ACTUAL_Y], moving[regs.IR_ACTUAL_Y + 1])
    assert 0 < x < 800 and -300 < y < 0
    assert moving[regs.IR_STATUS] & ENABLED and moving[regs.IR_HEARTBEAT] == 15
    assert regs.registers_to_int32(moving[regs.IR_TARGET_X], moving[regs.IR_TARGET_X + 1]) == 800
    assert result["clamped"][regs.IR_FAULTS] & FAULT_CLAMPED, "outside the workspace: flagged"
    assert silent[regs.IR_FAULTS] & FAULT_WATCHDOG and not silent[regs.IR_STATUS] & ENABLED
    assert result["bad"].isError(), "an address outside the map is an exception response"


def test_register_encoding_round_trips_negative_values() -> None:
    for value in (0, 1, -1, 123456, -98765, 2**31 - 1, -(2**31)):
        assert regs.registers_to_int32(*regs.int32_to_registers(value)) == value
