"""What the crane controller reports, and how it fails (pure: no Modbus here): the gantry's
cores (modes, safety, the loop) read a ``CraneReading``; the driver (``crane.py``) makes it."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

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
    setpoints_taken: int = 0  # the controller's count of setpoints it took (wraps at 65536)
    written_x_mm: float | None = None  # the setpoint registers as read back (None: not read)
    written_y_mm: float | None = None

    @property
    def enabled(self) -> bool:
        return bool(self.status & r.ENABLED)

    @property
    def moving(self) -> bool:
        return bool(self.status & r.MOVING)

    @property
    def watchdog_tripped(self) -> bool:
        return bool(self.faults & r.FAULT_WATCHDOG)

    @property
    def safety_ok(self) -> bool:
        """The controller's safety circuit is closed (no e-stop pressed)."""
        return bool(self.status & r.SAFETY_OK)

    @property
    def latched_faults(self) -> int:
        return self.faults & r.LATCHED_FAULTS

    @property
    def fault_names(self) -> str:
        return r.fault_names(self.faults)


class Crane(Protocol):
    """The crane controller as the gantry uses it: the Modbus driver here, a simulated one in
    the experiments. Every method raises ``CraneError`` when the controller cannot be used."""

    def read(self) -> CraneReading: ...

    def enable(self) -> None: ...

    def disable(self) -> None: ...

    def reset_faults(self) -> None: ...

    def write_setpoint(self, x_mm: float, y_mm: float) -> None: ...

    def heartbeat(self) -> None: ...
