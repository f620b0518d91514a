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
    HR_SETPOINT_X,
    HR_SETPOINT_Y,
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
                write_holding(self.model, now, address, len(values), after)
            elif function_code == _READ_INPUT:
                self.model.advance_to(now)
                registers[:IR_COUNT] = input_registers(self.model)
        return None



def write_holding(model: CraneModel, now: float, address: int, count: int,
                  holding: list[int]) -> None:
    """Play a write of ``count`` holding registers at ``address`` (``holding``: all of them,
    as they are after the write) against the model."""
    touched = set(range(address, address + count))
    if touched & {HR_SETPOINT_X, HR_SETPOINT_X + 1, HR_SETPOINT_Y, HR_SETPOINT_Y + 1}:
        model.write_setpoint(now, registers_to_int32(*holding[HR_SETPOINT_X:HR_SETPOINT_X + 2]),
                             registers_to_int32(*holding[HR_SETPOINT_Y:HR_SETPOINT_Y + 2]))
    if HR_CONTROL in touched:
        model.write_control(now, holding[HR_CONTROL])
    if HR_HEARTBEAT in touched:
        model.write_heartbeat(now, holding[HR_HEARTBEAT])


def input_registers(model: CraneModel) -> list[int]:
    """The input registers as the controller reports the model's state now."""
    target = model.position if model.target is None else model.target
    reported, velocity = model.reported, model.reported_velocity
    return (int32_to_registers(reported[0]) + int32_to_registers(reported[1])
            + int32_to_registers(velocity[0]) + int32_to_registers(velocity[1])
            + [model.status(), model.faults, model.heartbeat & 0xFFFF,
               model.setpoints_taken & 0xFFFF]
            + int32_to_registers(target[0]) + int32_to_registers(target[1]))
