"""What keeps the crane safe, whatever the predictor says (DESIGN §5; pure).

Every control period the guard turns a desired position into the setpoint actually sent:
non-finite or missing input, or an estimate older than ``stale_after_s``, → hold: the setpoint
freezes at the last one sent (where the crane is already going, so it stops there without
turning back; the crane's position if nothing was sent yet); otherwise the desired position
is clamped to the workspace (with a margin) and the setpoint's own motion is limited in speed
and acceleration, so a jump in the estimate never becomes a jump of the crane, and it closes
in on the desired position no faster than it can stop there (no overshoot of a robot that
stopped, whatever the lab's acceleration). The crane
controller's watchdog (heartbeat) covers a dead or cut-off gantry service.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np

from common.crane_registers import FAULT_CLAMPED
from common.volume import Box

if TYPE_CHECKING:  # the reading's type only: this module stays free of the Modbus driver
    from services.gantry.reading import CraneReading


@dataclass(frozen=True)
class Workspace:
    x_min_mm: float = -3000.0
    x_max_mm: float = 3000.0
    y_min_mm: float = -3000.0
    y_max_mm: float = 3000.0
    margin_mm: float = 50.0

    @cached_property
    def box(self) -> Box:
        """Where setpoints may go: the workspace less its margin."""
        return Box((self.x_min_mm, self.y_min_mm), (self.x_max_mm, self.y_max_mm)).shrunk(
            self.margin_mm)

    def clamp(self, xy: np.ndarray) -> np.ndarray:
        return np.array(self.box.clamp(xy))

    def contains(self, xy: np.ndarray) -> bool:
        return self.box.contains(xy)


@dataclass(frozen=True)
class Decision:
    setpoint: np.ndarray  # (x, y) mm, always inside the workspace
    hold: bool
    reason: str  # "" when tracking


@dataclass
class SetpointGuard:
    """The last word before a setpoint is written: inside the workspace, within the crane's
    speed and acceleration limits from where it was going, and held (frozen where the crane is
    already going) when the estimate is missing, not finite or stale."""

    workspace: Workspace = Workspace()
    max_speed_mm_s: float = 450.0
    max_accel_mm_s2: float = 550.0
    stale_after_s: float = 0.5
    _last: np.ndarray | None = None
    _step_velocity: np.ndarray = field(default_factory=lambda: np.zeros(2))
    _last_t: float | None = None
    _hold_at: np.ndarray | None = None
    _last_target: np.ndarray | None = None

    def reset(self) -> None:
        """Forget every earlier setpoint: after the crane stopped on its own (watchdog, link
        loss) the next setpoint starts from where it stands, never from where it was going."""
        self._last, self._last_t, self._hold_at, self._last_target = None, None, None, None
        self._step_velocity = np.zeros(2)

    def decide(self, now_s: float, desired: np.ndarray | None, measured_s: float | None,
               crane_xy: np.ndarray, *, max_speed_mm_s: float | None = None) -> Decision:
        """The setpoint to send; ``max_speed_mm_s`` lowers the speed limit for this step."""
        crane = self.workspace.clamp(np.nan_to_num(np.asarray(crane_xy, dtype=float)))
        reason = self._why_hold(now_s, desired, measured_s)
        if reason:
            if self._hold_at is None:  # freeze where the crane is already going: no reversal
                self._hold_at = crane if self._last is None else self._last
            self._last, self._last_t, self._last_target = self._hold_at, now_s, None
            self._step_velocity = np.zeros(2)
            return Decision(self._hold_at.copy(), True, reason)
        self._hold_at = None
        assert desired is not None
        target = self.workspace.clamp(np.asarray(desired, dtype=float))
        last = crane if self._last is None else self._last
        dt = 0.25 if self._last_t is None else max(now_s - self._last_t, 1e-3)
        speed = self.max_speed_mm_s if max_speed_mm_s is None else min(max_speed_mm_s,
                                                                        self.max_speed_mm_s)
        velocity = _limit((target - last) / dt, speed)
        velocity = self._step_velocity + _limit(velocity - self._step_velocity,
                                                self.max_accel_mm_s2 * dt)
        velocity = self._braking(velocity, target, last, dt, speed)
        if self._last_target is not None and not _same(target, self._last_target):
            # braking for a target that moved (back toward the crane) may ask for more than
            # the crane can: the acceleration limit comes first, it overshoots a little
            # instead (towards a target that stands, the braking profile keeps to the limit)
            velocity = self._step_velocity + _limit(velocity - self._step_velocity,
                                                    self.max_accel_mm_s2 * dt)
        setpoint = self.workspace.clamp(last + velocity * dt)
        self._step_velocity = (setpoint - last) / dt
        self._last, self._last_t, self._last_target = setpoint, now_s, target
        return Decision(setpoint, False, "")

    def _braking(self, velocity: np.ndarray, target: np.ndarray, last: np.ndarray, dt: float,
                 speed: float) -> np.ndarray:
        """``velocity`` capped so that the setpoint closes in on ``target`` no faster than it
        can still stop there at the acceleration limit, step by step (a target that moves is
        followed at its own velocity on top), and within the speed limit: a setpoint that
        would have to brake harder than the crane can never sends it past a robot that
        stopped."""
        moving = np.zeros(2) if self._last_target is None else _limit(
            (target - self._last_target) / dt, speed)
        gap = target - last
        distance = float(np.hypot(*gap))
        a = self.max_accel_mm_s2
        brake = min(math.sqrt(2 * a * distance + (a * dt / 2) ** 2) - a * dt / 2,
                    distance / dt)  # and never past it within this step
        closing = float(np.dot(velocity - moving, gap)) / distance if distance > 1e-9 else 0.0
        if closing > brake:  # only the closing part is capped; sideways stays
            velocity = velocity - (closing - brake) * gap / distance
        return _limit(velocity, speed)

    def _why_hold(self, now_s: float, desired: np.ndarray | None,
                  measured_s: float | None) -> str:
        if desired is None or measured_s is None:
            return "no estimate"
        if not np.all(np.isfinite(desired)) or np.shape(desired) != (2,):
            return "estimate is not a finite (x, y)"
        age = now_s - measured_s
        if age > self.stale_after_s:
            return f"estimate {age:.2f} s old"
        if age < -self.stale_after_s:
            return "estimate from the future (clocks?)"
        return ""


def _limit(vector: np.ndarray, norm: float) -> np.ndarray:
    length = float(np.hypot(*vector))
    return vector if length <= norm else vector * (norm / length)


class TargetCheck:
    """Whether the crane goes where the gantry sends it. Modbus/TCP has no authentication: a
    setpoint another client writes between two of the gantry's is taken by the controller
    like the gantry's own. Each time the controller reports a setpoint taken
    (``setpoints_taken`` changes), its target must be one of the setpoints the gantry wrote
    lately; ``persist`` targets in a row that are none of them → the reason to stop. A
    controller without those registers (constant values) is never judged. The gantry's
    setpoints stay inside its workspace, which lies inside the crane's: a clamped target is
    not one of them either. And
    at every poll the setpoint registers as read back must hold one of the gantry's
    setpoints: another client's write shows there at once, whether or not the controller
    takes it (``persist`` polls in a row): ``default`` writes just before the controller
    takes a setpoint, so a foreign client's write is taken seldom, but it is read back."""

    def __init__(self, tolerance_mm: float, persist: int = 2, remember: int = 8) -> None:
        self.tolerance_mm, self.persist = tolerance_mm, persist
        self._written: deque[tuple[float, float]] = deque(maxlen=remember)
        self._taken: int | None = None
        self._misses = 0
        self._foreign_polls = 0

    def wrote(self, x_mm: float, y_mm: float) -> None:
        self._written.append((x_mm, y_mm))

    def forget(self) -> None:
        """Before the crane is enabled: what was written before is no reference."""
        self._written.clear()
        self._taken, self._misses, self._foreign_polls = None, 0, 0

    def observe_written(self, reading: CraneReading) -> str | None:
        """The setpoint registers read back: none of the gantry's setpoints for ``persist``
        polls in a row → the reason to stop."""
        x, y = reading.written_x_mm, reading.written_y_mm
        if self.tolerance_mm <= 0 or x is None or y is None or not self._written:
            return None
        if self._ours(x, y):
            self._foreign_polls = 0
            return None
        self._foreign_polls += 1
        if self._foreign_polls < self.persist:
            return None
        return (f"the crane's setpoint registers hold ({x:.0f}, {y:.0f}) mm, none of the "
                f"gantry's setpoints, {self._foreign_polls} polls in a row: another Modbus "
                "client writes setpoints")

    def _ours(self, x: float, y: float) -> bool:
        return any(math.hypot(x - wx, y - wy) <= self.tolerance_mm for wx, wy in self._written)

    def observe(self, reading: CraneReading) -> str | None:
        taken, self._taken = self._taken, reading.setpoints_taken
        if self.tolerance_mm <= 0 or taken is None or taken == reading.setpoints_taken \
                or not self._written:
            return None
        x, y = reading.target_x_mm, reading.target_y_mm
        if self._ours(x, y):
            self._misses = 0
            return None
        self._misses += 1
        if self._misses < self.persist:
            return None
        clamped = " (clamped: set outside the crane's workspace)" \
            if reading.faults & FAULT_CLAMPED else ""
        return (f"the crane's target ({x:.0f}, {y:.0f}) mm{clamped} is none of the gantry's "
                f"setpoints {self._misses} times in a row: another Modbus client writes "
                "setpoints")


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    """``np.allclose(a, b)`` for two points, without its general machinery (each step asks)."""
    return all(abs(float(x) - float(y)) <= 1e-8 + 1e-5 * abs(float(y))
               for x, y in zip(a, b, strict=True))
