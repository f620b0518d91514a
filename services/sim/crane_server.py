"""The simulated crane controller on Modbus/TCP (pymodbus): the register map of docs/devices.md.

Every access is played against the ``CraneModel`` at the moment it arrives: writes become
model inputs, reads of the input registers report the model's state at that instant.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable

from pymodbus.server import ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

from common.crane_registers import (
    HR_CONTROL,
    HR_COUNT,
    HR_HEARTBEAT,
    IR_COUNT,
    int32_to_registers,
    registers_to_int32,
)
from services.sim.crane import CraneModel

log = logging.getLogger(__name__)

_READ_INPUT, _WRITE_CODES = 4, {6, 16, 23}


class CraneServer:
    """Serves a CraneModel (guarded by ``lock``) with ``clock()`` as the model's time."""

    def __init__(self, model: CraneModel, clock: Callable[[], float], lock: threading.Lock,
                 host: str = "127.0.0.1", port: int = 5020) -> None:
        self.model, self.clock, self.lock = model, clock, lock
        self.host, self.port = host, port
        self._device = SimDevice(
            id=0,
            simdata=([SimData(0, values=False, datatype=DataType.BITS)],
                     [SimData(0, values=False, datatype=DataType.BITS)],
                     [SimData(0, count=HR_COUNT, values=0, datatype=DataType.REGISTERS)],
                     [SimData(0, count=IR_COUNT, values=0, datatype=DataType.REGISTERS)]),
            action=self._access)
        self._server: ModbusTcpServer | None = None

    async def serve(self) -> None:
        """Listen and serve until closed (must run inside the event loop: pymodbus binds it)."""
        self._server = ModbusTcpServer(self._device, address=(self.host, self.port))
        log.info("crane controller (Modbus/TCP) on %s:%d", self.host, self.port)
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
                self._written(now, address, len(values), after)
            elif function_code == _READ_INPUT:
                self.model.advance_to(now)
                registers[:IR_COUNT] = self._input_registers()
        return None

    def _written(self, now: float, address: int, count: int, hr: list[int]) -> None:
        touched = set(range(address, address + count))
        if touched & {0, 1, 2, 3}:
            self.model.write_setpoint(now, registers_to_int32(hr[0], hr[1]),
                                      registers_to_int32(hr[2], hr[3]))
        if HR_CONTROL in touched:
            self.model.write_control(now, hr[HR_CONTROL])
        if HR_HEARTBEAT in touched:
            self.model.write_heartbeat(now, hr[HR_HEARTBEAT])

    def _input_registers(self) -> list[int]:
        m = self.model
        target = m.position if m.target is None else m.target
        return (int32_to_registers(m.reported[0]) + int32_to_registers(m.reported[1])
                + int32_to_registers(m.reported_velocity[0])
                + int32_to_registers(m.reported_velocity[1])
                + [m.status(), m.faults, m.heartbeat & 0xFFFF, m.setpoints_taken & 0xFFFF]
                + int32_to_registers(target[0]) + int32_to_registers(target[1]))
