"""What the operator must see at once (pure): the causes of alarm in what the page knows, each
with the time it began; an alarm that clears goes to a short log of the last few."""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from typing import Any

from common import messages as m

FRESH_S = 5.0
"""A crane report or offload figure older than this is not judged (the gantry publishes both
every cycle): a silent gantry is an alarm of its own."""


@dataclass(frozen=True)
class Alarm:
    key: str  # one per cause and subject: "offload", "service:gantry/main", "calib:ptz1"
    cause: str
    detail: str


def crane_alarms(crane: m.CraneState | None, estimate: m.RobotEstimate | None,
                 offload: m.GravityOffload | None, now_s: float) -> list[Alarm]:
    """Sideways pull, a stale estimate, a lost marker, a crane fault, the e-stop, a stopped
    gantry and a silent one."""
    out = []
    if offload is not None and offload.warning and now_s - offload.measured_s <= FRESH_S:
        out.append(Alarm("offload", "sideways pull",
                         f"{offload.horizontal_share_pct:.1f} % of the cable's pull "
                         f"(limit {offload.warn_above_pct:g} %), the crane "
                         f"{offload.horizontal_error_mm:.0f} mm off the robot"))
    if crane is None:
        return out
    age = now_s - crane.measured_s
    if age > FRESH_S:
        return [*out, Alarm("crane", "crane silent", f"no crane report for {age:.0f} s")]
    if crane.status == "holding":
        old = "" if estimate is None else \
            f": the robot's estimate is {now_s - estimate.measured_s:.1f} s old"
        out.append(Alarm("estimate", "estimate stale", f"the crane holds where it is{old}"))
    elif crane.status == "reacquiring":
        out.append(Alarm("estimate", "marker lost", "the tracking camera lost the robot's "
                         "marker: the crane goes to the motion capture's fix"))
    if crane.status == "unreachable":
        out.append(Alarm("crane", "crane fault", "the crane controller does not answer"))
    elif crane.status == "fault" or crane.fault_bits:
        out.append(Alarm("crane", "crane fault",
                         f"fault register 0x{crane.fault_bits:04x}: reset, then arm"))
    if not crane.safety_ok:
        out.append(Alarm("safety", "e-stop", "the crane's safety circuit is open"))
    if crane.mode == "stopped":
        by = f" ({crane.mode_by})" if crane.mode_by else ""
        out.append(Alarm("mode", "gantry stopped",
                         f"{crane.mode_reason or 'stopped'}{by}: reset, then arm"))
    return out


def service_alarms(services: list[dict[str, Any]]) -> list[Alarm]:
    """A service gone or degraded (rows as ``LiveState`` lists them)."""
    out = []
    for s in services:
        name = f"{s['service']}/{s['instance']}"
        if not s["alive"]:
            out.append(Alarm(f"service:{name}", "service down", f"{name} is gone"))
        elif s["status"] == "degraded":
            out.append(Alarm(f"service:{name}", "service degraded",
                             f"{name}: {s['detail'] or 'no reason given'}"))
    return out


def calibration_alarms(collections: dict[str, m.CollectProgress]) -> list[Alarm]:
    return [Alarm(f"calib:{camera}", "calibration failed", f"{camera}: {p.message}")
            for camera, p in collections.items() if p.state == "failed"]


@dataclass
class AlarmBoard:
    """The alarms now (each since it began) and the last ``keep`` that cleared."""

    keep: int = 8
    active: dict[str, tuple[Alarm, float]] = field(default_factory=dict)
    ended: deque[tuple[Alarm, float, float]] = field(default_factory=deque)

    def update(self, alarms: list[Alarm], now_s: float) -> None:
        """``alarms`` hold at ``now_s``: new ones begin, gone ones end; a changed detail
        keeps its start."""
        current = {a.key: a for a in alarms}
        for key, (alarm, since) in list(self.active.items()):
            if key not in current or current[key].cause != alarm.cause:
                del self.active[key]
                self.ended.append((alarm, since, now_s))
                while len(self.ended) > self.keep:
                    self.ended.popleft()
        for key, alarm in current.items():
            since = self.active.get(key, (alarm, now_s))[1]
            self.active[key] = (alarm, since)

    def view(self) -> dict[str, list[dict[str, Any]]]:
        return {
            "active": [{"cause": a.cause, "detail": a.detail, "since_s": since}
                       for a, since in sorted(self.active.values(), key=lambda e: e[1])],
            "ended": [{"cause": a.cause, "detail": a.detail, "since_s": since, "until_s": until}
                      for a, since, until in reversed(self.ended)]}
