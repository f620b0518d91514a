"""The crane controller's Modbus register map, defined once for the gantry's driver and the
sim's controller (docs/devices.md).

The built-in map is the default; a lab's PLC will number its registers otherwise, so every
address, the unit id, 16- or 32-bit values, their word order, signedness and scale come from
the lab file (``[gantry.crane.registers]``, and ``[sim.crane.registers]`` for the sim to serve
the same). The status, fault and control bits are fixed (docs/devices.md).
"""

from __future__ import annotations

import functools
from typing import Literal, Self

from pydantic import BaseModel, ConfigDict, Field, model_validator

# STATUS bits
ENABLED, MOVING, AT_TARGET, FAULTED, SAFETY_OK = 1, 2, 4, 8, 16
# FAULTS bits; the latched ones stay until a CONTROL_RESET
FAULT_WATCHDOG, FAULT_CLAMPED, FAULT_SAFETY = 1, 2, 4
LATCHED_FAULTS = FAULT_WATCHDOG | FAULT_SAFETY
FAULT_NAMES = {FAULT_WATCHDOG: "watchdog", FAULT_CLAMPED: "setpoint clamped",
               FAULT_SAFETY: "safety circuit"}
# CONTROL bits
CONTROL_ENABLE, CONTROL_RESET = 1, 2

HOLDING = ("setpoint_x", "setpoint_y", "control", "heartbeat")
INPUT = ("actual_x", "actual_y", "velocity_x", "velocity_y", "status", "faults",
         "heartbeat_echo", "setpoints_taken", "target_x", "target_y")
VALUES = {"setpoint_x", "setpoint_y", "actual_x", "actual_y", "velocity_x", "velocity_y",
          "target_x", "target_y"}
"""Registers holding positions (mm) or speeds (mm/s): ``value_bits`` wide, scaled; the others
are one 16-bit register each."""
MAX_READ = 125  # registers in one Modbus read


class RegisterMap(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)

    unit_id: int = Field(1, ge=0, le=247, description="Modbus unit (device) id")
    value_bits: Literal[16, 32] = Field(32, description="width of positions and speeds")
    signed: bool = True
    word_order: Literal["high_first", "low_first"] = Field(
        "high_first", description="32-bit values: which register holds the high word")
    units_per_mm: float = Field(1.0, gt=0, description="register units per mm (positions)")
    units_per_mm_s: float = Field(1.0, gt=0, description="register units per mm/s (speeds)")
    # holding registers (read/write: function codes 3, 6, 16)
    setpoint_x: int = Field(0, ge=0, le=65535)
    setpoint_y: int = Field(2, ge=0, le=65535)
    control: int = Field(4, ge=0, le=65535)
    heartbeat: int = Field(5, ge=0, le=65535)
    # input registers (read only: function code 4)
    actual_x: int = Field(0, ge=0, le=65535)
    actual_y: int = Field(2, ge=0, le=65535)
    velocity_x: int = Field(4, ge=0, le=65535)
    velocity_y: int = Field(6, ge=0, le=65535)
    status: int = Field(8, ge=0, le=65535)
    faults: int = Field(9, ge=0, le=65535)
    heartbeat_echo: int = Field(10, ge=0, le=65535)
    setpoints_taken: int = Field(11, ge=0, le=65535)
    target_x: int = Field(12, ge=0, le=65535)
    target_y: int = Field(14, ge=0, le=65535)

    @model_validator(mode="after")
    def _no_overlaps(self) -> Self:
        for names, kind in ((HOLDING, "holding"), (INPUT, "input")):
            taken: dict[int, str] = {}
            for name in names:
                for address in range(getattr(self, name), getattr(self, name) + self.width(name)):
                    if address in taken:
                        raise ValueError(f"{name}: {kind} register {address} is also "
                                         f"{taken[address]}'s")
                    taken[address] = name
            if kind == "input" and max(taken) - min(taken) + 1 > MAX_READ:
                raise ValueError(f"input registers span {min(taken)}–{max(taken)}: more than "
                                 f"one Modbus read ({MAX_READ})")
        return self

    def width(self, name: str) -> int:
        return self.value_bits // 16 if name in VALUES else 1

    @property
    def input_start(self) -> int:
        return _layout(self)[0]

    @property
    def input_count(self) -> int:
        return _layout(self)[1]

    @property
    def holding_count(self) -> int:
        return _layout(self)[2]

    def scale(self, name: str) -> float:
        return self.units_per_mm_s if name.startswith("velocity") else self.units_per_mm

    def encode(self, name: str, value: float) -> list[int]:
        """A position (mm) or speed (mm/s) as its registers; whole register units, clipped to
        what the registers hold."""
        bits = self.value_bits
        low, high = (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if self.signed else \
            (0, (1 << bits) - 1)
        raw = min(max(int(round(value * self.scale(name))), low), high) & ((1 << bits) - 1)
        if bits == 16:
            return [raw]
        words = [raw >> 16, raw & 0xFFFF]
        return words if self.word_order == "high_first" else words[::-1]

    def decode(self, name: str, registers: list[int]) -> float:
        """The registers of ``name`` (as many as its width) as mm or mm/s."""
        if self.value_bits == 16:
            raw, bits = registers[0], 16
        else:
            high, low = registers[:2] if self.word_order == "high_first" else registers[1::-1]
            raw, bits = (high << 16) | low, 32
        if self.signed and raw & (1 << (bits - 1)):
            raw -= 1 << bits
        return raw / self.scale(name)

    def read(self, name: str, block: list[int], start: int) -> float:
        """Value ``name`` from a block of registers read from address ``start``."""
        at = getattr(self, name) - start
        return self.decode(name, block[at:at + self.width(name)])


@functools.lru_cache(maxsize=32)
def _layout(registers: RegisterMap) -> tuple[int, int, int]:
    """(input_start, input_count, holding_count) of a map, worked out once per map (the gantry
    and the experiments read the crane 40 times a second)."""
    start = min(getattr(registers, n) for n in INPUT)
    count = max(getattr(registers, n) + registers.width(n) for n in INPUT) - start
    return start, count, max(getattr(registers, n) + registers.width(n) for n in HOLDING)


DEFAULT_MAP = RegisterMap()


def int32_to_registers(value: float) -> list[int]:
    """A signed 32-bit integer as two registers, high word first (the built-in map)."""
    return DEFAULT_MAP.encode("actual_x", value)


def registers_to_int32(high: int, low: int) -> int:
    return int(DEFAULT_MAP.decode("actual_x", [high, low]))


def fault_names(faults: int) -> str:
    return ", ".join(name for bit, name in FAULT_NAMES.items() if faults & bit) or "none"
