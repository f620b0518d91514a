"""The crane: its controller's behaviour on simulated time, and its Modbus/TCP wire."""

from __future__ import annotations

import asyncio
import struct
import threading
import time

import numpy as np
import pytest
from pymodbus.client import AsyncModbusTcpClient

from common import crane_registers as regs
from common.crane_registers import DEFAULT_MAP as MAP
from services.sim.crane import (
    CONTROL_ENABLE,
    CONTROL_RESET,
    ENABLED,
    FAULT_CLAMPED,
    FAULT_WATCHDOG,
    CraneModel,
    CraneParams,
    ramp_following_s,
)
from services.sim.crane_server import CraneServer
from tests.conftest import free_port, poll_async


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


def test_a_setpoint_is_taken_at_the_next_cycle_and_acted_on_a_dead_time_later() -> None:
    crane = _enabled(CraneParams(dead_time_s=0.3, cycle_s=0.25))
    crane.write_setpoint(0.01, 1000.0, 0.0)  # just after the cycle at 0: taken at 0.25
    track = _keep_alive(crane, 3.0, period=0.01)
    started = next(t for t, p in track if p[0] > 0.5)
    assert 0.25 + 0.3 <= started <= 0.25 + 0.3 + 0.05


def test_the_position_loop_lags_a_ramp_by_its_time_constant() -> None:
    crane = _enabled(CraneParams(dead_time_s=0.0, position_time_constant_s=0.2,
                                 cycle_s=0.05, max_speed_mm_s=1000, max_accel_mm_s2=5000))
    for k in range(1, 200):  # a setpoint ramp at 200 mm/s for 10 s
        t = 0.05 * k
        crane.write_setpoint(t, 200.0 * t, 0.0)
        crane.write_heartbeat(t, k)
    # the target is the setpoint written a cycle before (0.05 s) and steps every cycle (half
    # a cycle on average); the loop adds its time constant: speed = distance / τ
    lag = 200.0 * 9.95 - crane.position[0]
    assert lag == pytest.approx(200.0 * (0.05 + 0.025 + 0.2), abs=10.0)
    assert crane.velocity[0] == pytest.approx(200.0, abs=30.0)  # ripples with the steps


def test_the_reported_position_is_as_old_as_the_latency_give_or_take_the_jitter() -> None:
    latency, jitter = 0.1, 0.08
    crane = _enabled(CraneParams(report_latency_s=latency, report_jitter_s=jitter,
                                 dead_time_s=0.0))
    ages = []
    for k in range(1, 50):
        cycle = 0.25 * k
        crane.write_setpoint(cycle - 0.1, 200.0 * cycle, 0.0)
        crane.write_heartbeat(cycle - 0.1, k)
        crane.advance_to(cycle + 0.01)  # the controller publishes at its cycle
        ages.append(crane.published_s - crane.reported_s)
        assert crane.reported[0] == crane.position_at(crane.reported_s)[0]
    assert crane.reported[0] < crane.position[0] - 5, "moving: the report is behind"
    settled = np.array(ages[8:])
    assert settled.min() >= latency - jitter / 2 - 0.006
    assert settled.max() <= latency + jitter / 2 + 0.006
    assert settled.std() > jitter / 6, "not one fixed age (uniform: jitter / √12)"


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


async def _connected(port: int, timeout_s: float = 10.0
                     ) -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
    """A connection to the server as soon as it listens (it starts on the same loop)."""
    async def connection() -> tuple[asyncio.StreamReader, asyncio.StreamWriter] | None:
        try:
            return await asyncio.open_connection("127.0.0.1", port)
        except OSError:
            return None

    connected = await poll_async(connection, timeout_s)
    assert connected is not None, f"nothing listens on {port} after {timeout_s:g} s"
    return connected


def test_modbus_client_drives_the_crane_over_tcp() -> None:
    """A Modbus client over TCP, on a clock the test moves on: the crane model's time is
    what the test says, however busy the machine."""
    port = free_port()
    now = [0.0]

    def clock() -> float:
        return now[0]

    crane = CraneModel(CraneParams(watchdog_s=0.5, x_max_mm=3000.0, max_accel_mm_s2=600.0,
                                   dead_time_s=0.5))
    server = CraneServer(crane, clock, threading.Lock(), "127.0.0.1", port)

    async def main() -> dict:
        serving = asyncio.create_task(server.serve())
        (await _connected(port))[1].close()
        client = AsyncModbusTcpClient("127.0.0.1", port=port, timeout=2)
        await client.connect()
        try:
            await client.write_register(MAP.control, CONTROL_ENABLE)
            await client.write_registers(MAP.setpoint_x, regs.int32_to_registers(800)
                                         + regs.int32_to_registers(-300))
            now[0] += 0.3
            early = (await client.read_input_registers(0, count=MAP.input_count)).registers
            for beat in range(1, 16):
                now[0] += 0.1
                await client.write_register(MAP.heartbeat, beat)
            moving = (await client.read_input_registers(0, count=MAP.input_count)).registers
            await client.write_registers(MAP.setpoint_x, regs.int32_to_registers(9000)
                                         + regs.int32_to_registers(0))
            now[0] += 0.3
            clamped = (await client.read_input_registers(0, count=MAP.input_count)).registers
            now[0] += 1.0  # a second without heartbeats: the watchdog trips
            silent = (await client.read_input_registers(0, count=MAP.input_count)).registers
            bad = await client.read_input_registers(100, count=2)
            return {"early": early, "moving": moving, "clamped": clamped, "silent": silent,
                    "bad": bad}
        finally:
            client.close()
            await server.close()
            serving.cancel()

    result = asyncio.run(main())
    early, moving, silent = result["early"], result["moving"], result["silent"]
    assert early[MAP.actual_x: MAP.actual_x + 4] == [0, 0, 0, 0], "0.5 s dead time"
    x = regs.registers_to_int32(moving[MAP.actual_x], moving[MAP.actual_x + 1])
    y = regs.registers_to_int32(moving[MAP.actual_y], moving[MAP.actual_y + 1])
    assert 0 < x < 800 and -300 < y < 0
    assert moving[MAP.status] & ENABLED and moving[MAP.heartbeat_echo] == 15
    assert regs.registers_to_int32(moving[MAP.target_x], moving[MAP.target_x + 1]) == 800
    assert result["clamped"][MAP.faults] & FAULT_CLAMPED, "outside the workspace: flagged"
    assert silent[MAP.faults] & FAULT_WATCHDOG and not silent[MAP.status] & ENABLED
    assert result["bad"].isError(), "an address outside the map is an exception response"


def test_register_encoding_round_trips_negative_values() -> None:
    for value in (0, 1, -1, 123456, -98765, 2**31 - 1, -(2**31)):
        assert regs.registers_to_int32(*regs.int32_to_registers(value)) == value


def test_the_ramp_following_time_is_dead_time_and_loop_lag_unless_acceleration_shapes_it(
        ) -> None:
    """What ``stb gantry identify`` measures as the reaction (setpoint taken → the crane
    follows): the dead time and at most the first-order loop's time constant where the
    acceleration limit does not matter; more where each cycle's step is acceleration-limited."""
    free = CraneParams(dead_time_s=0.1, position_time_constant_s=0.05, max_accel_mm_s2=1e6)
    assert 0.1 <= ramp_following_s(free) <= 0.1 + 0.05 + 0.01
    limited = CraneParams(dead_time_s=0.1, position_time_constant_s=0.05,
                          max_accel_mm_s2=800.0)
    assert ramp_following_s(limited) > ramp_following_s(free) + 0.05


def test_the_sim_stopping_with_a_gantry_connected_logs_no_error(
        caplog: pytest.LogCaptureFixture) -> None:
    """The sim ends its event loop with the gantry's Modbus connection open (`stb up` stopped,
    a benchmark's end): the connection's task is cancelled, which asyncio's stream callback
    (Python 3.11) used to log as an error with a traceback."""
    port = free_port()
    server = CraneServer(CraneModel(CraneParams()), time.monotonic, threading.Lock(),
                         "127.0.0.1", port)

    async def main() -> None:
        asyncio.create_task(server.serve())  # noqa: RUF006 - asyncio.run cancels it at the end
        reader, writer = await _connected(port)
        # one read of an input register (Modbus/TCP: its header, function 4): once answered,
        # the server's task for this connection waits for the next request
        writer.write(struct.pack(">HHHBBHH", 1, 0, 6, MAP.unit_id, 4, MAP.input_start, 1))
        await writer.drain()
        transaction, _, length = struct.unpack(">HHH", await asyncio.wait_for(
            reader.readexactly(6), 10))
        assert transaction == 1 and len(await reader.readexactly(length)) == length
        # returning now, the connection open: asyncio.run cancels the server and its task

    with caplog.at_level("ERROR"):
        asyncio.run(main())
    assert [r.getMessage() for r in caplog.records if r.levelname == "ERROR"] == []


def test_the_state_at_a_time_the_crane_has_moved_past_is_its_history() -> None:
    """A thread that read the clock, then waited while another advanced the crane (a Modbus
    request), gets the state at its time, not the later one (the live truth once did)."""
    crane = _enabled()
    for t in (0.01, 0.3, 0.6):  # within the watchdog's 0.5 s
        crane.write_setpoint(t, 800.0, -300.0)
    crane.advance_to(0.7)
    then = (crane.position.copy(), crane.velocity.copy())
    assert np.hypot(*then[1]) > 50, "moving"
    crane.write_setpoint(1.0, 800.0, -300.0)
    crane.advance_to(1.1)
    position, velocity = crane.state_at(0.7)
    assert position == pytest.approx(then[0]) and velocity == pytest.approx(then[1])
    assert not np.allclose(crane.position, then[0])
