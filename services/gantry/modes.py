"""Who may move the crane (pure): the gantry's modes, the operator's commands, the stops.

* ``disarmed`` — at start, and after ``disarm`` or ``reset``. The gantry never enables the
  crane: it measures and estimates, and writes nothing to the controller.
* ``armed`` — only after an operator's ``arm`` (which needs a fresh estimate of the robot:
  its marker in view, or the motion capture's fix, from which the gantry finds it; and the
  geometry trusted: the crane's position through its frame agreeing with the motion
  capture's marker on the carriage, the tracking camera's fix with the motion capture's robot
  — ``crosscheck.py``): tracking when it has a fresh estimate, holding otherwise.
* ``stopped`` — after ``stop`` (accepted in every mode), or by itself when the crane stops
  on its own: a watchdog trip or another latched fault, the safety circuit open (e-stop), or
  the crane disabled at the controller; or when the crane goes where the gantry did not send
  it (another Modbus client's setpoints, ``TargetCheck``), or its reported position
  disagrees with the motion capture's marker on the carriage for ``check_window_s``. The
  setpoint is frozen where the crane is and the crane is disabled. Only ``reset`` (which
  clears the controller's latched faults) leads out, to ``disarmed``; then ``arm``. The
  gantry never resets a fault on its own.

Every change names who asked and why. What the gantry says of itself follows from its mode
too: the status it publishes with the crane's state (``crane_status``), its health
(``health``) and whether it feeds the crane's watchdog (``heartbeat_due``).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

from common.messages import CraneStatus, HealthStatus
from common.names import GantryCommandName, GantryMode
from services.gantry.reading import CraneReading


class Action(StrEnum):
    """What the loop does to the crane controller for a decision."""

    NONE = "none"
    ENABLE = "enable"
    DISABLE = "disable"
    FREEZE_AND_DISABLE = "freeze and disable"  # setpoint := where it is; then disable
    RESET_FAULTS = "reset faults"


@dataclass(frozen=True)
class Decision:
    accepted: bool
    mode: GantryMode  # the mode after it
    action: Action
    detail: str  # why: the refusal's reason, or what changed


@dataclass(frozen=True)
class Facts:
    """What arming depends on, as the loop sees it now."""

    crane: CraneReading | None  # None: the controller does not answer
    estimate_age_s: float | None  # None: no estimate of the robot from the tracking camera
    stale_after_s: float
    fix_age_s: float | None = None  # the motion capture's fix of the robot (None: none)
    geometry: str | None = None  # why the crane's frame or the camera's model is not trusted


class ModeKeeper:
    def __init__(self, now_s: float, enable_grace_s: float = 1.0) -> None:
        self.mode: GantryMode = "disarmed"
        self.by, self.reason, self.since_s = "gantry", "started: disarmed until an operator " \
            "arms it", now_s
        self.enable_grace_s = enable_grace_s
        self._armed_at_s = now_s

    def command(self, command: GantryCommandName, by: str, reason: str, now_s: float, facts: Facts
                ) -> Decision:
        """An operator's command: accepted (and what to do) or refused (and why)."""
        if command == "stop":
            return self._change("stopped", Action.FREEZE_AND_DISABLE, by,
                                reason or "stop", now_s)
        if command == "reset":
            if self.mode == "armed":
                return self._refuse("armed: disarm or stop before a reset")
            return self._change("disarmed", Action.RESET_FAULTS, by,
                                reason or "reset", now_s)
        if command == "disarm":
            if self.mode == "stopped":
                return self._refuse("stopped: reset first")
            if self.mode == "disarmed":
                return Decision(True, self.mode, Action.NONE, "already disarmed")
            return self._change("disarmed", Action.DISABLE, by, reason or "disarm", now_s)
        return self._arm(by, reason, now_s, facts)

    def observe(self, crane: CraneReading, now_s: float) -> Decision | None:
        """The controller's report while armed: a stop if the crane stopped on its own."""
        if self.mode != "armed":
            return None
        why = stopped_why(crane)
        if why is None and not crane.enabled and now_s - self._armed_at_s > self.enable_grace_s:
            why = "crane disabled at the controller"
        if why is None:
            return None
        return self._change("stopped", Action.FREEZE_AND_DISABLE, "crane", why, now_s)

    def halt(self, why: str, now_s: float) -> Decision:
        """The gantry stops the crane by itself (what it saw is ``why``), as a stop would."""
        return self._change("stopped", Action.FREEZE_AND_DISABLE, "gantry", why, now_s)

    def _arm(self, by: str, reason: str, now_s: float, facts: Facts) -> Decision:
        if self.mode == "armed":
            return Decision(True, self.mode, Action.NONE, "already armed")
        if self.mode == "stopped":
            return self._refuse("stopped: reset first")
        if facts.crane is None:
            return self._refuse("the crane controller does not answer")
        why = stopped_why(facts.crane)
        if why is not None:
            return self._refuse(f"{why}: reset first")
        if not any(age is not None and age <= facts.stale_after_s
                   for age in (facts.estimate_age_s, facts.fix_age_s)):
            return self._refuse("no fresh estimate of the robot: its marker is not in the "
                                "tracking camera's view and the motion capture has no fix")
        if facts.geometry is not None:
            return self._refuse(facts.geometry)
        self._armed_at_s = now_s
        return self._change("armed", Action.ENABLE, by, reason or "arm", now_s)

    def _change(self, mode: GantryMode, action: Action, by: str, reason: str, now_s: float
                ) -> Decision:
        self.mode, self.by, self.reason, self.since_s = mode, by, reason, now_s
        return Decision(True, mode, action, reason)

    def _refuse(self, why: str) -> Decision:
        return Decision(False, self.mode, Action.NONE, why)


def stopped_why(crane: CraneReading) -> str | None:
    """Why the controller will not move the crane (latched faults, the safety circuit), or
    None."""
    if not crane.safety_ok:
        return "safety circuit open (e-stop)"
    if crane.latched_faults:
        return f"crane fault latched ({crane.fault_names})"
    return None


def crane_status(mode: GantryMode, reading: CraneReading, *, hold: bool, reacquiring: bool = False
                 ) -> CraneStatus:
    """What the crane's state says the gantry is doing: a latched fault shows unless the
    gantry is stopped (then the stop says more: who and why)."""
    if reading.latched_faults and mode != "stopped":
        return "fault"
    if mode == "disarmed":
        return "idle"
    if mode == "stopped":
        return "stopped"
    if hold:
        return "holding"
    return "reacquiring" if reacquiring else "tracking"


def health(keeper: ModeKeeper, *, untrusted: str | None, disagreement: str, hold: bool,
           hold_reason: str) -> tuple[HealthStatus, str]:
    """The gantry's health while the controller answers: degraded when stopped, when it would
    not arm (``untrusted``: why the geometry is not trusted), when the tracking camera and the
    motion capture disagree, or while it holds (``hold_reason``)."""
    if keeper.mode == "stopped":
        return "degraded", f"stopped by {keeper.by}: {keeper.reason}"
    if keeper.mode == "disarmed":
        if untrusted:
            return "degraded", f"disarmed; would not arm: {untrusted}"
        return "ok", "disarmed"
    if disagreement:
        return "degraded", disagreement
    return ("degraded" if hold else "ok"), hold_reason


def heartbeat_due(armed: bool, since_last_step_s: float, control_hz: float) -> bool:
    """The crane's watchdog is fed only while armed and the control loop is alive (a step in
    the last 2.5 periods): a stuck or failing loop stops the heartbeat, and the crane's
    watchdog stops the crane."""
    return armed and since_last_step_s <= 2.5 / control_hz
