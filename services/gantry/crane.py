"""The crane controller over Modbus/TCP (pymodbus): the register map of docs/devices.md.

One client, one lock: the control loop and the heartbeat share the connection. Every failure
is a ``CraneUnreachable`` (transport) or ``CraneRejected`` (a Modbus exception reply).
"""

from __future__ import annotations

import contextlib
import socket
import struct
import threading
from dataclasses import dataclass
from typing import Protocol

from pymodbus.client import ModbusTcpClient
from pymodbus.exceptions import ModbusException

from common import crane_registers as r


class CraneError(Exception):
    """The crane controller cannot be used right now."""


class CraneUnreachable(CraneError):
    pass


class CraneRejected(CraneError):
    pass


@dataclass(frozen=True)
class CraneReading:
    x_mm: float
    y_mm: float
    vx_mm_s: float
    vy_mm_s: float
    status: int
    faults: int
    target_x_mm: float
    target_y_mm: float

    @property
    def enabled(self) -> bool:
        return bool(self.status & r.ENABLED)

    @property
    def moving(self) -> bool:
        return bool(self.status & r.MOVING)

    @property
    def watchdog_tripped(self) -> bool:
        return bool(self.faults & r.FAULT_WATCHDOG)


def reading_from(v: list[int]) -> CraneReading:
    """The controller's input registers (from address 0) as a reading."""
    def i32(at: int) -> float:
        return float(r.registers_to_int32(v[at], v[at + 1]))

    return CraneReading(i32(r.IR_ACTUAL_X), i32(r.IR_ACTUAL_Y), i32(r.IR_VELOCITY_X),
                        i32(r.IR_VELOCITY_Y), v[r.IR_STATUS], v[r.IR_FAULTS],
                        i32(r.IR_TARGET_X), i32(r.IR_TARGET_Y))


class Crane(Protocol):
    """The crane controller as the gantry uses it: the Modbus driver here, a simulated one in
    the experiments. Every method raises ``CraneError`` when the controller cannot be used."""

    def read(self) -> CraneReading: ...

    def enable(self) -> None: ...

    def disable(self) -> None: ...

    def write_setpoint(self, x_mm: float, y_mm: float) -> None: ...

    def heartbeat(self) -> None: ...


class ModbusCrane:
    def __init__(self, host: str, port: int, timeout_s: float = 0.5) -> None:
        self.host, self.port = host, port
        self._client = ModbusTcpClient(host, port=port, timeout=timeout_s, retries=0)
        self._lock = threading.Lock()
        self._beat = 0

    def enable(self) -> None:
        """Reset faults and enable; the controller drops whatever setpoint it had queued."""
        self._write(r.HR_CONTROL, [r.CONTROL_ENABLE | r.CONTROL_RESET])

    def disable(self) -> None:
        self._write(r.HR_CONTROL, [0])

    def write_setpoint(self, x_mm: float, y_mm: float) -> None:
        self._write(r.HR_SETPOINT_X, r.int32_to_registers(x_mm) + r.int32_to_registers(y_mm))

    def heartbeat(self) -> None:
        self._beat = (self._beat + 1) % 65536
        self._write(r.HR_HEARTBEAT, [self._beat])

    def read(self) -> CraneReading:
        with self._lock:
            reply = self._call(lambda: self._client.read_input_registers(0, count=r.IR_COUNT))
        return reading_from(reply.registers)

    def close(self) -> None:
        with self._lock:
            self._client.close()

    def _write(self, address: int, values: list[int]) -> None:
        with self._lock:
            self._call(lambda: self._client.write_registers(address, values))

    def _call(self, request):  # type: ignore[no-untyped-def]
        try:
            if not self._client.connected and not self._client.connect():
                raise CraneUnreachable(f"crane controller {self.host}:{self.port} not reachable")
            reply = request()
        except (ModbusException, OSError) as err:
            self._abort()
            raise CraneUnreachable(f"crane controller {self.host}:{self.port}: {err}") from err
        if reply.isError():
            raise CraneRejected(f"crane controller refused the request: {reply}")
        return reply

    def _abort(self) -> None:
        """Close with a reset, dropping whatever is still unsent: a write that timed out must
        never reach the controller later, when the link is back (it would be stale)."""
        sock = getattr(self._client, "socket", None)
        if sock is not None:
            with contextlib.suppress(OSError):
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
        self._client.close()
