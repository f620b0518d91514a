"""The simulated crane controller on Modbus/TCP: the lab's register map
(``common.crane_registers.RegisterMap``, docs/devices.md) on unit ``unit_id``, answered as
the Modbus specification says (``services.sim.modbus``): only the documented registers exist.

Every access is played against the ``CraneModel`` at the moment it arrives: writes become
model inputs, reads of the input registers report the model's state at that instant. One
holding register that no PLC has, ``estop_register``, is the sim's own e-stop button: 1
presses it (the safety circuit opens), 0 releases it (``stb sim estop``).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import threading
from collections.abc import Callable

from common.crane_registers import DEFAULT_MAP, HOLDING, RegisterMap
from services.sim import modbus
from services.sim.crane import CraneModel

log = logging.getLogger(__name__)

ESTOP_REGISTER = 100


class CraneRegisters:
    """The controller's registers over a CraneModel (guarded by ``lock``)."""

    def __init__(self, model: CraneModel, clock: Callable[[], float], lock: threading.Lock,
                 registers: RegisterMap, estop_register: int) -> None:
        self.model, self.clock, self.lock = model, clock, lock
        self.registers, self.estop_register = registers, estop_register
        self.holding = frozenset({*_addresses(registers, HOLDING), estop_register})
        # The input registers are one block, read in one request: a lab map's gaps in it read 0.
        self.inputs = frozenset(range(registers.input_start,
                                      registers.input_start + registers.input_count))
        self._values = [0] * (max(self.holding) + 1)

    def read_holding(self, address: int, count: int) -> list[int]:
        with self.lock:
            return self._values[address:address + count]

    def read_input(self, address: int, count: int) -> list[int]:
        now, start = self.clock(), self.registers.input_start
        with self.lock:
            self.model.advance_to(now)
            block = input_registers(self.model, self.registers)
        return block[address - start:address - start + count]

    def write(self, address: int, values: list[int]) -> None:
        now = self.clock()
        touched = range(address, address + len(values))
        with self.lock:
            self._values[address:address + len(values)] = values
            write_holding(self.model, now, touched, self._values, self.registers)
            if self.estop_register in touched:
                self.model.set_safety_circuit(now, not self._values[self.estop_register])


def _addresses(registers: RegisterMap, names: tuple[str, ...]) -> set[int]:
    return {a for n in names
            for a in range(getattr(registers, n), getattr(registers, n) + registers.width(n))}


class CraneServer:
    """Serves a CraneModel (guarded by ``lock``) with ``clock()`` as the model's time."""

    def __init__(self, model: CraneModel, clock: Callable[[], float], lock: threading.Lock,
                 host: str = "127.0.0.1", port: int = 5020, *,
                 registers: RegisterMap = DEFAULT_MAP,
                 estop_register: int = ESTOP_REGISTER) -> None:
        self.model, self.clock, self.lock = model, clock, lock
        self.host, self.port = host, port
        self.registers, self.estop_register = registers, estop_register
        self.device = CraneRegisters(model, clock, lock, registers, estop_register)
        self._server: asyncio.Server | None = None
        self._closing = False

    async def serve(self) -> None:
        """Listen and serve until closed (inside the device loop's event loop)."""
        self._server = await asyncio.start_server(self._connection, self.host, self.port)
        log.info("crane controller (Modbus/TCP) on %s:%d, unit %d", self.host, self.port,
                 self.registers.unit_id)
        try:
            await self._server.serve_forever()
        except asyncio.CancelledError:
            if not self._closing:
                raise

    async def close(self) -> None:
        self._closing = True
        if self._server is not None:
            self._server.close()
            with contextlib.suppress(Exception):
                await self._server.wait_closed()

    async def _connection(self, reader: asyncio.StreamReader,
                          writer: asyncio.StreamWriter) -> None:
        buffer = bytearray()
        try:
            while chunk := await reader.read(4096):
                buffer += chunk
                for request in modbus.split_requests(buffer):
                    writer.write(modbus.frame(request, self._answer(request)))
                await writer.drain()
        except modbus.BadFrame as err:
            log.debug("crane controller: not Modbus/TCP (%s): connection closed", err)
        except (ConnectionError, OSError):
            pass
        except asyncio.CancelledError:
            # The sim is stopping with a gantry connected. Ending the task normally keeps
            # asyncio's stream callback (Python 3.11) from logging the cancellation as an error.
            pass
        finally:
            writer.close()

    def _answer(self, request: modbus.Request) -> bytes:
        function = request.pdu[0] if request.pdu else 0
        if request.unit != self.registers.unit_id:
            return modbus.exception(function, modbus.GATEWAY_TARGET_FAILED)
        try:
            return modbus.answer(request.pdu, self.device)
        except Exception:  # a fault of the sim's own: answered, as a PLC does, and logged
            log.exception("crane controller: failed to serve function %d", function)
            return modbus.exception(function, modbus.DEVICE_FAILURE)


def write_holding(model: CraneModel, now: float, touched: range, holding: list[int],
                  registers: RegisterMap = DEFAULT_MAP) -> None:
    """Play a write of the holding registers ``touched`` (``holding``: all of them from
    address 0, as they are after the write) against the model."""
    def value(name: str) -> float:
        return registers.read(name, holding, 0)

    def hit(name: str) -> bool:
        first = getattr(registers, name)
        return any(a in touched for a in range(first, first + registers.width(name)))

    if hit("setpoint_x") or hit("setpoint_y"):
        model.write_setpoint(now, value("setpoint_x"), value("setpoint_y"))
    if hit("control"):
        model.write_control(now, holding[registers.control])
    if hit("heartbeat"):
        model.write_heartbeat(now, holding[registers.heartbeat])


def input_registers(model: CraneModel, registers: RegisterMap = DEFAULT_MAP) -> list[int]:
    """The input registers (from ``registers.input_start``) as the controller reports the
    model's state now."""
    (x, y, vx, vy), target = model.report()
    block = [0] * registers.input_count
    start, r = registers.input_start, registers
    for name, v in (("actual_x", x), ("actual_y", y), ("velocity_x", vx), ("velocity_y", vy),
                    ("target_x", target[0]), ("target_y", target[1])):
        at, words = getattr(r, name) - start, r.encode(name, v)
        block[at:at + len(words)] = words
    block[r.status - start] = model.status()
    block[r.faults - start] = model.faults
    block[r.heartbeat_echo - start] = model.heartbeat & 0xFFFF
    block[r.setpoints_taken - start] = model.setpoints_taken & 0xFFFF
    return block
