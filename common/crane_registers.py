"""The crane controller's Modbus register map (docs/devices.md), defined once for the gantry's
driver and the sim's controller. 32-bit values are two registers, high word first, signed."""

from __future__ import annotations

# Holding registers (read/write): function codes 3, 6, 16.
HR_SETPOINT_X, HR_SETPOINT_Y, HR_CONTROL, HR_HEARTBEAT, HR_COUNT = 0, 2, 4, 5, 6
# Input registers (read only): function code 4.
IR_ACTUAL_X, IR_ACTUAL_Y, IR_VELOCITY_X, IR_VELOCITY_Y = 0, 2, 4, 6
IR_STATUS, IR_FAULTS, IR_HEARTBEAT, IR_SETPOINTS_TAKEN = 8, 9, 10, 11
IR_TARGET_X, IR_TARGET_Y, IR_COUNT = 12, 14, 16

# STATUS bits
ENABLED, MOVING, AT_TARGET, FAULTED = 1, 2, 4, 8
# FAULTS bits
FAULT_WATCHDOG, FAULT_CLAMPED = 1, 2
# CONTROL bits
CONTROL_ENABLE, CONTROL_RESET = 1, 2


def int32_to_registers(value: float) -> list[int]:
    """A signed 32-bit integer as two registers, high word first."""
    raw = int(round(value)) & 0xFFFFFFFF
    return [raw >> 16, raw & 0xFFFF]


def registers_to_int32(high: int, low: int) -> int:
    raw = (high << 16) | low
    return raw - (1 << 32) if raw & 0x80000000 else raw
