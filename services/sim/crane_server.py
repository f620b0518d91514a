"""The simulated crane controller on Modbus/TCP (pymodbus): the lab's register map
(``common.crane_registers.RegisterMap``, docs/devices.md) on unit ``unit_id``.

Every access is played against the ``CraneModel`` at the moment it arrives: writes become
model inputs, reads of the input registers report the model's state at that instant. One
holding register that no PLC has, ``estop_register``, is the sim's own e-stop button: 1
presses it (the safety circuit opens), 0 releases it (``stb sim estop``).
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable

from pymodbus.server import ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

from common.crane_registers import DEFAULT_MAP, RegisterMap
from services.sim.crane import CraneModel

log = logging.getLogger(__name__)

_READ_INPUT, _WRITE_CODES = 4, {6, 16, 23}
ESTOP_REGISTER = 100


class CraneServer:
    """Serves a CraneModel (guarded by ``lock``) with ``clock()`` as the model's time."""

    def __init__(self, model: CraneModel, clock: Callable[[], float], lock: threading.Lock,
                 host: str = "127.0.0.1", port: int = 5020, *,
                 registers: RegisterMap = DEFAULT_MAP,
                 estop_register: int = ESTOP_REGISTER) -> None:
        self.model, self.clock, self.lock = model, clock, lock
        self.host, self.port = host, port
        self.registers, self.estop_register = registers, estop_register
        holding = max(registers.holding_count, estop_register + 1)
        self._device = SimDevice(
            id=registers.unit_id,
            simdata=([SimData(0, values=False, datatype=DataType.BITS)],
                     [SimData(0, values=False, datatype=DataType.BITS)],
                     [SimData(0, count=holding, values=0, datatype=DataType.REGISTERS)],
                     [SimData(registers.input_start, count=registers.input_count, values=0,
                              datatype=DataType.REGISTERS)]),
            action=self._access)
        self._server: ModbusTcpServer | None = None

    async def serve(self) -> None:
        """Listen and serve until closed (must run inside the event loop: pymodbus binds it)."""
        self._server = ModbusTcpServer(self._device, address=(self.host, self.port))
        log.info("crane controller (Modbus/TCP) on %s:%d, unit %d", self.host, self.port,
                 self.registers.unit_id)
        await self._server.serve_forever()

    async def close(self) -> None:
        if self._server is not None:
            await self._server.shutdown()

    async def _access(self, function_code: int, start: int, address: int, count: int,
                      registers: list[int], values: list[int] | list[bool] | None) -> None:
        now = self.clock()
        with self.lock:
            if function_code in _WRITE_CODES and values is not None:
                after = list(registers)
                after[address - start: address - start + len(values)] = [int(v) for v in values]
                touched = range(address, address + len(values))
                write_holding(self.model, now, touched, after, self.registers)
                if self.estop_register in touched:
                    self.model.set_safety_circuit(now, not after[self.estop_register])
            elif function_code == _READ_INPUT:
                self.model.advance_to(now)
                registers[:] = input_registers(self.model, self.registers)
        return None


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
    target = model.position if model.target is None else model.target
    reported, velocity = model.reported, model.reported_velocity
    block = [0] * registers.input_count
    values = {"actual_x": reported[0], "actual_y": reported[1], "velocity_x": velocity[0],
              "velocity_y": velocity[1], "target_x": target[0], "target_y": target[1]}
    words = {"status": model.status(), "faults": model.faults,
             "heartbeat_echo": model.heartbeat & 0xFFFF,
             "setpoints_taken": model.setpoints_taken & 0xFFFF}
    start = registers.input_start
    for name, v in values.items():
        at = getattr(registers, name) - start
        block[at:at + registers.width(name)] = registers.encode(name, v)
    for name, w in words.items():
        block[getattr(registers, name) - start] = w
    return block
