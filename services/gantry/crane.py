"""The crane controller over Modbus/TCP (pymodbus), through the lab's register map
(``common.crane_registers.RegisterMap``; docs/devices.md) and the crane's frame
(``common.crane_frame.CraneFrame``): this is the one place where the crane's own coordinates
become the world's and back — readings in, setpoints out. Everything above it (the control
law, the guard, the workspace, reacquire, the offload figures, the page) is in the world's.

One client, one lock: the control loop and the heartbeat share the connection. Every failure
is a ``CraneUnreachable`` (transport) or ``CraneRejected`` (a Modbus exception reply).
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import socket
import struct
import threading
from collections.abc import Callable
from typing import Any

from pymodbus.client import ModbusTcpClient
from pymodbus.exceptions import ModbusException

from common import crane_registers as r
from common.crane_frame import CRANE_COUNTS_IN_THE_WORLD, CraneFrame
from common.crane_registers import DEFAULT_MAP, RegisterMap
from services.gantry.reading import CraneReading, CraneRejected, CraneUnreachable

log = logging.getLogger(__name__)

def reading_from(block: list[int], start: int, registers: RegisterMap = DEFAULT_MAP,
                 frame: CraneFrame = CRANE_COUNTS_IN_THE_WORLD) -> CraneReading:
    """The controller's input registers (a block read from address ``start``) as a reading in
    the world's coordinates."""
    def value(name: str) -> float:
        return registers.read(name, block, start)

    def word(name: str) -> int:
        return block[getattr(registers, name) - start]

    position = frame.to_world([value("actual_x"), value("actual_y")])
    velocity = frame.vector_to_world([value("velocity_x"), value("velocity_y")])
    target = frame.to_world([value("target_x"), value("target_y")])
    return CraneReading(float(position[0]), float(position[1]), float(velocity[0]),
                        float(velocity[1]), word("status"), word("faults"), float(target[0]),
                        float(target[1]), word("setpoints_taken"))


def setpoint_writes(registers: RegisterMap, x_mm: float, y_mm: float,
                    frame: CraneFrame = CRANE_COUNTS_IN_THE_WORLD) -> list[tuple[int, list[int]]]:
    """(address, values) writes of a setpoint given in the world: one write when x and y are
    adjacent, so that the controller never samples half of it."""
    x_c, y_c = frame.to_crane([x_mm, y_mm])
    x, y = registers.encode("setpoint_x", x_c), registers.encode("setpoint_y", y_c)
    if registers.setpoint_y == registers.setpoint_x + len(x):
        return [(registers.setpoint_x, x + y)]
    return [(registers.setpoint_x, x), (registers.setpoint_y, y)]


class RegisterCrane:
    """The ``Crane`` Protocol over a register map and the crane's frame (positions in the
    world's coordinates; ``frame=CraneFrame()``: the crane's own); a subclass moves the
    registers (Modbus/TCP here, the sim's model in the experiments)."""

    def __init__(self, registers: RegisterMap,
                 frame: CraneFrame = CRANE_COUNTS_IN_THE_WORLD) -> None:
        self.registers, self.frame = registers, frame
        self._beat = 0
        self.reads_back = True  # the setpoint registers, at each read
        # the last blocks read and what they said: a controller's registers change once a
        # cycle, and the loop reads them several times a cycle (40 a second)
        self._decoded: tuple[tuple[int, ...], CraneReading] | None = None
        self._read_back: tuple[tuple[int, ...], tuple[float, float]] | None = None

    def enable(self) -> None:
        """Enable only: a latched fault stays latched (``reset_faults`` is the operator's)."""
        self._write(self.registers.control, [r.CONTROL_ENABLE])

    def disable(self) -> None:
        self._write(self.registers.control, [0])

    def reset_faults(self) -> None:
        """Clear the controller's latched faults; the crane stays disabled."""
        self._write(self.registers.control, [r.CONTROL_RESET])

    def write_setpoint(self, x_mm: float, y_mm: float) -> None:
        for address, values in setpoint_writes(self.registers, x_mm, y_mm, self.frame):
            self._write(address, values)

    def heartbeat(self) -> None:
        self._beat = (self._beat + 1) % 65536
        self._write(self.registers.heartbeat, [self._beat])

    def read(self) -> CraneReading:
        """The input registers, and the setpoint registers read back: whoever wrote them
        last, the gantry or another Modbus client."""
        block = tuple(self._read_input())
        if self._decoded is None or self._decoded[0] != block:
            self._decoded = block, reading_from(list(block), self.registers.input_start,
                                                self.registers, self.frame)
        reading = self._decoded[1]
        if not self.reads_back:
            return reading
        try:
            held = tuple(word for name in ("setpoint_x", "setpoint_y") for word in
                         self._read_holding(getattr(self.registers, name),
                                            self.registers.width(name)))
        except CraneRejected as err:  # a controller that does not let its setpoints be read
            log.warning("the setpoint registers cannot be read back (%s): the gantry judges "
                        "only the targets the controller takes", err)
            self.reads_back = False
            return reading
        if self._read_back is None or self._read_back[0] != held:
            self._read_back = held, self._written(list(held))
        x, y = self._read_back[1]
        return dataclasses.replace(reading, written_x_mm=x, written_y_mm=y)

    def _written(self, held: list[int]) -> tuple[float, float]:
        """The setpoint registers (x's words, then y's) in the world."""
        width = self.registers.width("setpoint_x")
        x = self.registers.read("setpoint_x", held[:width], self.registers.setpoint_x)
        y = self.registers.read("setpoint_y", held[width:], self.registers.setpoint_y)
        written = self.frame.to_world([x, y])
        return float(written[0]), float(written[1])

    def _write(self, address: int, values: list[int]) -> None:
        raise NotImplementedError

    def _read_holding(self, start: int, count: int) -> list[int]:
        """``count`` holding registers from ``start``."""
        raise NotImplementedError

    def _read_input(self) -> list[int]:
        """The input registers from ``registers.input_start``, ``input_count`` of them."""
        raise NotImplementedError


class ModbusCrane(RegisterCrane):
    """The crane controller over Modbus/TCP (pymodbus): the register map's reads and writes on
    one connection, reconnecting when it drops; errors are ``CraneError``."""

    def __init__(self, host: str, port: int, timeout_s: float = 0.5,
                 registers: RegisterMap = DEFAULT_MAP,
                 frame: CraneFrame = CRANE_COUNTS_IN_THE_WORLD) -> None:
        super().__init__(registers, frame)
        self.host, self.port = host, port
        self._client = ModbusTcpClient(host, port=port, timeout=timeout_s, retries=0)
        self._lock = threading.Lock()

    def _read_input(self) -> list[int]:
        start, count = self.registers.input_start, self.registers.input_count
        with self._lock:
            reply = self._call(lambda: self._client.read_input_registers(
                start, count=count, device_id=self.registers.unit_id))
        return reply.registers

    def _read_holding(self, start: int, count: int) -> list[int]:
        with self._lock:
            reply = self._call(lambda: self._client.read_holding_registers(
                start, count=count, device_id=self.registers.unit_id))
        return reply.registers

    def close(self) -> None:
        with self._lock:
            self._client.close()

    def _write(self, address: int, values: list[int]) -> None:
        with self._lock:
            self._call(lambda: self._client.write_registers(address, values,
                                                            device_id=self.registers.unit_id))

    def _call(self, request: Callable[[], Any]) -> Any:
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
