"""The gantry crane as its controller behaves (pure, on an injected time; fixed 5 ms steps).

* The controller runs a cycle of ``cycle_s`` (4 Hz, paper §3.2). At each cycle it samples the
  setpoint registers; a sampled setpoint becomes the axes' target ``dead_time_s`` later.
* Each axis has a position loop: it runs towards its target at the target's distance divided
  by ``position_time_constant_s`` (0: as fast as the limits allow), within its speed and
  acceleration limits and the workspace; setpoints outside it are clamped and flagged.
* At each cycle the controller also publishes the position it has from the drives — measured
  ``report_latency_s`` earlier, give or take ``report_jitter_s / 2`` (the paper: "the delay and
  exact time of measurement of the gantry crane is roughly known").
* Watchdog: while enabled, if neither a setpoint write nor a heartbeat change arrives for
  ``watchdog_s``, the crane brakes to a stop, disables itself and latches a fault. It moves
  again only after a fault reset and a new enable.
* Safety circuit: an e-stop opens it; the crane brakes to a stop, disables itself and latches
  a safety fault, which a reset clears only once the circuit is closed again. Enabling is
  refused while a latched fault or an open circuit remains.

Parameter values and where they come from: docs/experiments.md (identified against the
paper's Tables 3–4 with ``stb experiment identify``) and docs/devices.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np

from common.crane_registers import (  # noqa: F401 - its users import the bits from here
    AT_TARGET,
    CONTROL_ENABLE,
    CONTROL_RESET,
    ENABLED,
    FAULT_CLAMPED,
    FAULT_SAFETY,
    FAULT_WATCHDOG,
    FAULTED,
    LATCHED_FAULTS,
    MOVING,
    SAFETY_OK,
)
from common.volume import Box

STEP_S = 0.005
HISTORY_S = 2.0
"""How far back ``position_at`` can look: report latency and jitter, a tracking frame's age."""


@dataclass(frozen=True)
class CraneParams:
    """The defaults are the crane identified against the paper's Tables 3–4
    (``stb experiment identify``, docs/experiments.md); the 4 Hz cycle is the paper's."""

    x_min_mm: float = -3000.0
    x_max_mm: float = 3000.0
    y_min_mm: float = -3000.0
    y_max_mm: float = 3000.0
    max_speed_mm_s: float = 520.0
    max_accel_mm_s2: float = 2080.0
    cycle_s: float = 0.25
    dead_time_s: float = 0.006
    position_time_constant_s: float = 0.027
    report_latency_s: float = 0.05
    report_jitter_s: float = 0.078
    watchdog_s: float = 0.5

    @property
    def reaction_s(self) -> float:
        """How long after a setpoint is written the crane follows it, on average: half a
        cycle until it is sampled, the dead time, the position loop's lag on a ramp."""
        return 0.5 * self.cycle_s + self.dead_time_s + self.position_time_constant_s

    @cached_property
    def travel(self) -> Box:
        return Box((self.x_min_mm, self.y_min_mm), (self.x_max_mm, self.y_max_mm))

    def clamp(self, x_mm: float, y_mm: float) -> tuple[float, float, bool]:
        cx, cy = self.travel.clamp((x_mm, y_mm))
        return cx, cy, (cx, cy) != (x_mm, y_mm)


@dataclass
class CraneModel:
    params: CraneParams = CraneParams()
    rng: np.random.Generator = field(default_factory=lambda: np.random.default_rng(0))
    """Draws the report's timing jitter."""
    enabled: bool = False
    safety_ok: bool = True  # the safety circuit is closed (no e-stop pressed)
    faults: int = 0
    heartbeat: int = 0
    setpoints_taken: int = 0
    reported_s: float = 0.0
    """When the position the controller reports now was measured."""
    published_s: float = 0.0
    """When the controller published it (its last cycle)."""
    _p: list[float] = field(default_factory=lambda: [0.0, 0.0])
    _v: list[float] = field(default_factory=lambda: [0.0, 0.0])
    _target: list[float] | None = None
    _written: tuple[float, float] | None = None  # setpoint registers as last written
    _last_activity: float = 0.0
    _pending: list[tuple[int, tuple[float, float]]] = field(default_factory=list)
    _step: int = 0
    _next_cycle_step: int = 0  # in whole steps: the cycle does not drift with rounding
    _reported: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)  # x, y, vx, vy
    _history: list[tuple[float, float, float, float]] = field(init=False)
    """(x, y, vx, vy) at the end of step i, at [i % its length]."""

    def __post_init__(self) -> None:
        self._history = [(0.0, 0.0, 0.0, 0.0)] * int(round(HISTORY_S / STEP_S))

    @property
    def time(self) -> float:
        return self._step * STEP_S

    @property
    def position(self) -> np.ndarray:
        return np.array(self._p)

    @property
    def velocity(self) -> np.ndarray:
        return np.array(self._v)

    @property
    def target(self) -> np.ndarray | None:
        return None if self._target is None else np.array(self._target)

    @property
    def reported(self) -> np.ndarray:
        """Position as the controller reports it (published once per cycle, like a PLC's
        process image; measured ``report_latency_s`` ± jitter before)."""
        return np.array(self._reported[:2])

    @property
    def reported_velocity(self) -> np.ndarray:
        return np.array(self._reported[2:])

    def report(self) -> tuple[tuple[float, float, float, float], tuple[float, float]]:
        """What the controller reports, as plain numbers (the register server asks 40 times a
        second): (x, y, vx, vy) as ``reported`` and ``reported_velocity``, and the target
        (where it stands when it has none)."""
        target = self._target if self._target is not None else self._p
        return self._reported, (target[0], target[1])

    def place(self, x_mm: float, y_mm: float) -> None:
        """Start at rest at (x, y), clamped to the travel, and report it from the start
        (not (0, 0) until the first cycle)."""
        x, y, _ = self.params.clamp(x_mm, y_mm)
        self._p, self._v = [x, y], [0.0, 0.0]
        self._reported = (x, y, 0.0, 0.0)
        self._history = [(x, y, 0.0, 0.0)] * len(self._history)

    def position_at(self, t: float) -> np.ndarray:
        """Where the crane was at ``t`` (at most ``HISTORY_S`` ago; clamped to that)."""
        return self.state_at(t)[0]

    def state_at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(position, velocity) at ``t`` (at most ``HISTORY_S`` ago; clamped to that): the
        crane may have been advanced past ``t`` by another thread (a Modbus request)."""
        step = min(max(int(round(t / STEP_S)), self._step - len(self._history) + 1, 0),
                   self._step)
        x, y, vx, vy = self._history[step % len(self._history)]
        return np.array([x, y]), np.array([vx, vy])

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
            self.faults = 0 if self.safety_ok else FAULT_SAFETY
        if value & CONTROL_ENABLE and not self.faults & LATCHED_FAULTS and self.safety_ok:
            if not self.enabled:
                self._last_activity = now
                self._pending.clear()
                self._written = None
                self._target = None
            self.enabled = True
        elif not value & CONTROL_ENABLE:
            self.enabled = False
            self._target = list(self._p)

    def set_safety_circuit(self, now: float, closed: bool) -> None:
        """Open (an e-stop pressed) or close the safety circuit."""
        self.advance_to(now)
        if not closed:
            self._stop_with(FAULT_SAFETY)
        self.safety_ok = closed

    # --- time ----------------------------------------------------------------------------

    def advance_to(self, now: float) -> None:
        last = int(math.floor(now / STEP_S + 1e-9))
        while self._step < last:
            self._step += 1
            self._tick(self._step * STEP_S)

    def _tick(self, t: float) -> None:
        p = self.params
        if self.enabled and t - self._last_activity > p.watchdog_s:
            self._stop_with(FAULT_WATCHDOG)
        if self._step >= self._next_cycle_step:
            self._cycle(t)
        while self._pending and self._pending[0][0] <= self._step:
            self._target = list(self._pending.pop(0)[1])
        self._move()
        pos, vel = self._p, self._v
        self._history[self._step % len(self._history)] = (pos[0], pos[1], vel[0], vel[1])

    def _stop_with(self, fault: int) -> None:
        self.enabled = False
        self.faults |= fault
        self._pending.clear()
        self._target = None  # brake to a stop

    def _cycle(self, t: float) -> None:
        p = self.params
        self._next_cycle_step = self._step + max(1, round(p.cycle_s / STEP_S))
        age = p.report_latency_s
        if p.report_jitter_s > 0:
            age += self.rng.uniform(-0.5, 0.5) * p.report_jitter_s
        # the state at the end of step i is history[i]; this step has not moved yet
        measured = max(self._step - max(int(round(age / STEP_S)), 1),
                       self._step - len(self._history) + 1)
        self._reported = self._history[measured % len(self._history)]
        self.reported_s, self.published_s = measured * STEP_S, t
        if self.enabled and self._written is not None:
            x, y, clamped = p.clamp(*self._written)
            self.faults = (self.faults | FAULT_CLAMPED) if clamped else (
                self.faults & ~FAULT_CLAMPED)
            self._pending.append((self._step + int(round(p.dead_time_s / STEP_S)), (x, y)))
            self.setpoints_taken += 1

    def _move(self) -> None:
        p = self.params
        dv_max = p.max_accel_mm_s2 * STEP_S
        target = None if not self.enabled else self._target
        for axis, low, high in ((0, p.x_min_mm, p.x_max_mm), (1, p.y_min_mm, p.y_max_mm)):
            pos, vel = self._p[axis], self._v[axis]
            desired = 0.0 if target is None else _desired_speed(target[axis] - pos, p, dv_max)
            vel += min(max(desired - vel, -dv_max), dv_max)
            pos += vel * STEP_S
            if pos < low or pos > high:
                pos, vel = min(max(pos, low), high), 0.0
            self._p[axis], self._v[axis] = pos, vel

    # --- what the controller reports ---------------------------------------------------------

    def status(self) -> int:
        moving = abs(self._v[0]) > 0.5 or abs(self._v[1]) > 0.5
        at_target = self._target is not None and all(
            abs(self._target[i] - self._p[i]) < 1.0 for i in (0, 1))
        return ((ENABLED if self.enabled else 0) | (MOVING if moving else 0)
                | (AT_TARGET if at_target else 0) | (FAULTED if self.faults else 0)
                | (SAFETY_OK if self.safety_ok else 0))


def _desired_speed(error: float, p: CraneParams, dv_max: float) -> float:
    """The position loop's speed towards a target ``error`` mm away: proportional (or flat
    out), never faster than the limit nor than it can brake within the distance left."""
    if abs(error) < 0.5 * dv_max * STEP_S + 1e-9:
        return error / STEP_S
    limit = min(p.max_speed_mm_s, math.sqrt(2 * p.max_accel_mm_s2 * abs(error)))
    tau = p.position_time_constant_s
    speed = abs(error) / tau if tau > 0 else limit
    return math.copysign(min(speed, limit), error)


def ramp_following_s(params: CraneParams, speed_mm_s: float = 100.0, write_every_s: float = 0.05,
                     settle_s: float = 1.5, ramp_s: float = 4.0) -> float:
    """How long after the controller takes a setpoint this crane follows a ramp — what
    ``stb gantry identify`` measures and sets as ``[gantry] reaction_s``: the crane's mean lag
    behind a ramp written every ``write_every_s``, once it has caught up, less half a cycle
    (the mean wait until a written setpoint is taken). More than the dead time and the
    position loop's time constant wherever the acceleration limit shapes each cycle's step."""
    model = CraneModel(replace(params, report_jitter_s=0.0, watchdog_s=3600.0))
    model.write_control(0.0, CONTROL_ENABLE)
    lags, t = [], 0.0
    while t < settle_s + ramp_s:
        written = speed_mm_s * t
        model.write_setpoint(t, written, 0.0)
        model.advance_to(t)
        if t >= settle_s:
            lags.append((written - float(model.position[0])) / speed_mm_s)
        t += write_every_s
    return float(np.mean(lags)) - params.cycle_s / 2
