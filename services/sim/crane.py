"""The gantry crane as its controller behaves (pure, on an injected time; fixed 5 ms steps).

* The controller samples the setpoint registers once per cycle (4 Hz); a sampled setpoint
  becomes the motion target ``reaction_s`` (0.5 s) later — the paper's measured delay.
* Each axis moves towards its target with velocity and acceleration limits and never leaves
  the workspace; setpoints outside it are clamped and flagged.
* Watchdog: while enabled, if neither a setpoint write nor a heartbeat change arrives for
  ``watchdog_s``, the crane brakes to a stop, disables itself and latches a fault. It moves
  again only after a fault reset and a new enable.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from common.crane_registers import (  # noqa: F401 - its users import the bits from here
    AT_TARGET,
    CONTROL_ENABLE,
    CONTROL_RESET,
    ENABLED,
    FAULT_CLAMPED,
    FAULT_WATCHDOG,
    FAULTED,
    MOVING,
)

STEP_S = 0.005



@dataclass(frozen=True)
class CraneParams:
    x_min_mm: float = -3000.0
    x_max_mm: float = 3000.0
    y_min_mm: float = -3000.0
    y_max_mm: float = 3000.0
    max_speed_mm_s: float = 500.0
    max_accel_mm_s2: float = 2500.0
    reaction_s: float = 0.5
    cycle_s: float = 0.25
    watchdog_s: float = 0.5

    def clamp(self, x_mm: float, y_mm: float) -> tuple[float, float, bool]:
        cx = min(max(x_mm, self.x_min_mm), self.x_max_mm)
        cy = min(max(y_mm, self.y_min_mm), self.y_max_mm)
        return cx, cy, (cx, cy) != (x_mm, y_mm)


@dataclass
class CraneModel:
    params: CraneParams = CraneParams()
    position: np.ndarray = field(default_factory=lambda: np.zeros(2))
    velocity: np.ndarray = field(default_factory=lambda: np.zeros(2))
    target: np.ndarray | None = None
    enabled: bool = False
    faults: int = 0
    heartbeat: int = 0
    setpoints_taken: int = 0
    _written: tuple[float, float] | None = None  # setpoint registers as last written
    _last_activity: float = 0.0
    _pending: list[tuple[float, np.ndarray]] = field(default_factory=list)
    _step: int = 0
    _next_cycle_step: int = 0  # in whole steps: the cycle does not drift with rounding
    reported: np.ndarray = field(default_factory=lambda: np.zeros(2))
    """Position as the controller reports it: measured once per cycle (4 Hz), like a PLC's
    process image — up to one cycle old when read (the paper: the crane's time of
    measurement is only roughly known)."""
    reported_velocity: np.ndarray = field(default_factory=lambda: np.zeros(2))
    reported_s: float = 0.0  # when ``reported`` was measured

    @property
    def time(self) -> float:
        return self._step * STEP_S

    def place(self, x_mm: float, y_mm: float) -> None:
        """Start at rest at (x, y), clamped to the travel, and report it from the start
        (not (0, 0) until the first cycle)."""
        x, y, _ = self.params.clamp(x_mm, y_mm)
        self.position = np.array([x, y], dtype=float)
        self.velocity = np.zeros(2)
        self.reported, self.reported_velocity = self.position.copy(), self.velocity.copy()

    # --- register writes -----------------------------------------------------------------

    def write_setpoint(self, now: float, x_mm: float, y_mm: float) -> None:
        self.advance_to(now)
        self._written = (x_mm, y_mm)
        self._last_activity = now

    def write_heartbeat(self, now: float, value: int) -> None:
        self.advance_to(now)
        if value != self.heartbeat:
            self.heartbeat = value
            self._last_activity = now

    def write_control(self, now: float, value: int) -> None:
        self.advance_to(now)
        if value & CONTROL_RESET:
            self.faults = 0
        if value & CONTROL_ENABLE and not self.faults & FAULT_WATCHDOG:
            if not self.enabled:
                self._last_activity = now
                self._pending.clear()
                self._written = None
                self.target = None
            self.enabled = True
        elif not value & CONTROL_ENABLE:
            self.enabled = False
            self.target = self.position.copy()

    # --- time ----------------------------------------------------------------------------

    def advance_to(self, now: float) -> None:
        while (self._step + 1) * STEP_S <= now + 1e-12:
            self._step += 1
            self._tick(self.time)

    def _tick(self, t: float) -> None:
        p = self.params
        if self.enabled and t - self._last_activity > p.watchdog_s:
            self.enabled = False
            self.faults |= FAULT_WATCHDOG
            self._pending.clear()
            self.target = None  # brake to a stop
        if self._step >= self._next_cycle_step:
            self._next_cycle_step = self._step + max(1, round(p.cycle_s / STEP_S))
            self.reported, self.reported_velocity = self.position.copy(), self.velocity.copy()
            self.reported_s = t
            if self.enabled and self._written is not None:
                x, y, clamped = p.clamp(*self._written)
                self.faults = (self.faults | FAULT_CLAMPED) if clamped else (
                    self.faults & ~FAULT_CLAMPED)
                self._pending.append((t + p.reaction_s, np.array([x, y])))
                self.setpoints_taken += 1
        while self._pending and self._pending[0][0] <= t:
            self.target = self._pending.pop(0)[1]
        self._move()

    def _move(self) -> None:
        p = self.params
        dv_max = p.max_accel_mm_s2 * STEP_S
        if self.target is None or not self.enabled:
            desired = np.zeros(2)  # brake
        else:
            error = self.target - self.position
            reachable = np.sqrt(2 * p.max_accel_mm_s2 * np.abs(error))
            desired = np.sign(error) * np.minimum(p.max_speed_mm_s, reachable)
            close = np.abs(error) < 0.5 * dv_max * STEP_S + 1e-9
            desired[close] = error[close] / STEP_S
        self.velocity += np.clip(desired - self.velocity, -dv_max, dv_max)
        self.position += self.velocity * STEP_S
        low = np.array([p.x_min_mm, p.y_min_mm])
        high = np.array([p.x_max_mm, p.y_max_mm])
        outside = (self.position < low) | (self.position > high)
        self.position = np.clip(self.position, low, high)
        self.velocity[outside] = 0.0

    # --- what the controller reports ---------------------------------------------------------

    def status(self) -> int:
        moving = bool(np.any(np.abs(self.velocity) > 0.5))
        at_target = self.target is not None and bool(
            np.all(np.abs(self.target - self.position) < 1.0))
        return ((ENABLED if self.enabled else 0) | (MOVING if moving else 0)
                | (AT_TARGET if at_target else 0) | (FAULTED if self.faults else 0))
