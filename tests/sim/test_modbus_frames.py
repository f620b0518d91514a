"""The simulated crane controller answers raw Modbus/TCP frames as the specification says:
only the documented registers exist; anything else gets FC | 0x80 and the right exception."""

from __future__ import annotations

import asyncio
import socket
import struct
import threading
import time
from collections.abc import Iterator

import pytest
from pymodbus.client import ModbusTcpClient

from common.crane_registers import DEFAULT_MAP as MAP
from services.sim.crane import CraneModel, CraneParams
from services.sim.crane_server import ESTOP_REGISTER, CraneServer
from tests.conftest import free_port, wait_for
from tests.ports import listening


@pytest.fixture
def controller() -> Iterator[int]:
    port, loop, t0 = free_port(), asyncio.new_event_loop(), time.monotonic()
    server = CraneServer(CraneModel(CraneParams()), lambda: time.monotonic() - t0,
                         threading.Lock(), "127.0.0.1", port)
    thread = threading.Thread(target=loop.run_until_complete, args=(server.serve(),),
                              daemon=True)
    thread.start()
    wait_for(lambda: listening(port), timeout=5, period=0.05)
    yield port
    asyncio.run_coroutine_threadsafe(server.close(), loop).result(5)
    thread.join(5)


def _ask(port: int, pdu: bytes, unit: int = MAP.unit_id, transaction: int = 7) -> bytes:
    """The response PDU to ``pdu`` (checked: same transaction and unit, length right)."""
    with socket.create_connection(("127.0.0.1", port), timeout=2) as link:
        link.sendall(struct.pack(">HHHB", transaction, 0, len(pdu) + 1, unit) + pdu)
        return _reply(link, transaction, unit)


def _reply(link: socket.socket, transaction: int, unit: int) -> bytes:
    header = _exactly(link, 7)
    got_transaction, protocol, length, got_unit = struct.unpack(">HHHB", header)
    assert (got_transaction, protocol, got_unit) == (transaction, 0, unit)
    return _exactly(link, length - 1)


def _exactly(link: socket.socket, size: int) -> bytes:
    data = b""
    while len(data) < size:
        chunk = link.recv(size - len(data))
        assert chunk, "the controller closed the connection"
        data += chunk
    return data


def _read(function: int, address: int, count: int) -> bytes:
    return struct.pack(">BHH", function, address, count)


def _write_many(address: int, values: list[int], count: int | None = None,
                size: int | None = None) -> bytes:
    count = len(values) if count is None else count
    size = 2 * len(values) if size is None else size
    return struct.pack(f">BHHB{len(values)}H", 16, address, count, size, *values)


def test_the_documented_registers_read_and_write(controller: int) -> None:
    holding = _ask(controller, _read(3, 0, MAP.holding_count))
    assert holding[:2] == bytes([3, 2 * MAP.holding_count])
    inputs = _ask(controller, _read(4, MAP.input_start, MAP.input_count))
    assert inputs[:2] == bytes([4, 2 * MAP.input_count])
    echo = struct.pack(">BHH", 6, MAP.heartbeat, 42)
    assert _ask(controller, echo) == echo
    assert _ask(controller, _read(3, MAP.heartbeat, 1)) == bytes([3, 2, 0, 42])
    assert _ask(controller, _write_many(MAP.setpoint_x, [0, 100, 0, 200])) == \
        struct.pack(">BHH", 16, MAP.setpoint_x, 4)
    assert _ask(controller, _read(3, ESTOP_REGISTER, 1)) == bytes([3, 2, 0, 0])


@pytest.mark.parametrize("function", [1, 2, 5, 7, 8, 11, 15, 17, 20, 21, 22, 23, 24, 43, 0x41])
def test_any_other_function_code_is_illegal(controller: int, function: int) -> None:
    assert _ask(controller, bytes([function, 0, 0, 0, 1])) == bytes([function | 0x80, 1])


@pytest.mark.parametrize(("pdu", "code"), [
    (_read(4, 0, 0), 3),  # quantity 0
    (_read(4, 0, 126), 3),  # more than one read may carry
    (_read(3, 0, 0), 3),
    (bytes([4, 0, 0, 0]), 3),  # a PDU too short
    (_read(4, MAP.input_start + MAP.input_count, 1), 2),  # past the input registers
    (_read(4, MAP.input_start + MAP.input_count - 1, 2), 2),  # runs past them
    (_read(3, MAP.holding_count, 1), 2),  # no holding register there
    (_read(3, ESTOP_REGISTER - 1, 2), 2),
    (struct.pack(">BHH", 6, 50, 1), 2),
    (struct.pack(">BHHB", 6, MAP.control, 1, 0), 3),  # FC 6 with a byte too many
    (_write_many(MAP.setpoint_x, [1, 2], count=3), 3),  # count and data disagree
    (_write_many(MAP.setpoint_x, [1, 2], size=5), 3),
    (_write_many(MAP.setpoint_x, []), 3),  # quantity 0
    (_write_many(MAP.heartbeat, [1, 2]), 2),  # runs past the last holding register
])
def test_bad_quantities_and_addresses_get_their_exception(controller: int, pdu: bytes,
                                                          code: int) -> None:
    assert _ask(controller, pdu) == bytes([pdu[0] | 0x80, code])


def test_another_unit_is_answered_as_a_gateway_would(controller: int) -> None:
    assert _ask(controller, _read(4, 0, 1), unit=MAP.unit_id + 1) == bytes([0x84, 0x0B])


def test_frames_split_or_joined_in_tcp_are_answered_each(controller: int) -> None:
    first = struct.pack(">HHHB", 1, 0, 6, MAP.unit_id) + _read(3, 0, 2)
    second = struct.pack(">HHHB", 2, 0, 6, MAP.unit_id) + _read(4, 0, 1)
    with socket.create_connection(("127.0.0.1", controller), timeout=2) as link:
        link.sendall(first + second[:4])
        time.sleep(0.1)  # the rest in a TCP segment of its own: the split is the subject
        link.sendall(second[4:])
        assert _reply(link, 1, MAP.unit_id)[:2] == bytes([3, 4])
        assert _reply(link, 2, MAP.unit_id)[:2] == bytes([4, 2])


def test_a_frame_that_is_not_modbus_tcp_closes_the_connection(controller: int) -> None:
    with socket.create_connection(("127.0.0.1", controller), timeout=2) as link:
        link.sendall(struct.pack(">HHHB", 1, 5, 6, MAP.unit_id) + _read(3, 0, 1))
        assert link.recv(16) == b""
    assert _ask(controller, _read(3, 0, 1))[:2] == bytes([3, 2]), "the controller serves on"


def test_pymodbus_sees_the_exceptions_as_the_spec_names_them(controller: int) -> None:
    client = ModbusTcpClient("127.0.0.1", port=controller, timeout=2, retries=0)
    assert client.connect()
    try:
        past = client.read_input_registers(MAP.input_start + MAP.input_count, count=1,
                                           device_id=MAP.unit_id)
        assert past.isError() and past.function_code == 0x84 and past.exception_code == 2
        coils = client.read_coils(0, count=1, device_id=MAP.unit_id)
        assert coils.isError() and coils.function_code == 0x81 and coils.exception_code == 1
        fine = client.read_input_registers(MAP.input_start, count=MAP.input_count,
                                           device_id=MAP.unit_id)
        assert not fine.isError() and len(fine.registers) == MAP.input_count
    finally:
        client.close()
