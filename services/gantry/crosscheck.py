"""Two position channels compared crosswise, as drive safety functions do (pure; every clock is
an argument): a tolerance, a window, a named reason.

The gantry keeps two:

* **crane** — the crane's position as its controller reports it, through the crane's frame
  (``[gantry.crane]``), against the motion capture's marker on the carriage. A disagreement
  means the frame is not this crane's (or the controller's counts slipped): the gantry
  refuses to arm and, armed, stops the crane (latched: an operator resets it).
* **tracking** — the tracking camera's fix of the robot, through the camera's lens and mount
  (``[gantry.tracking_camera]``), against the motion capture's robot. A disagreement means a
  wrong camera model, a stray reflection or a spoofed frame: the gantry refuses to arm on it
  and, armed, does not use such fixes (it holds, or goes by the motion capture) until the two
  agree again.

A comparison beyond the tolerance counts only when it lasts: ``failing`` once the channel has
disagreed for ``window_s`` without an agreeing comparison in between (a single stray sample
is not a fault). ``verdict`` (for arming) needs a recent comparison and its agreement.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Disagreement:
    channel: str
    off_mm: float
    since_s: float
    tolerance_mm: float
    remedy: str

    def text(self, now_s: float) -> str:
        return (f"{self.channel} disagrees with the motion capture by {self.off_mm:.0f} mm "
                f"(tolerance {self.tolerance_mm:.0f} mm, for {now_s - self.since_s:.1f} s): "
                f"{self.remedy}")


class CrossCheck:
    def __init__(self, channel: str, tolerance_mm: float, window_s: float, fresh_s: float,
                 remedy: str) -> None:
        self.channel, self.tolerance_mm, self.window_s = channel, tolerance_mm, window_s
        self.fresh_s, self.remedy = fresh_s, remedy
        self.off_mm: float | None = None  # the last comparison's difference
        self.compared_s: float | None = None  # when
        self._beyond_since: float | None = None

    @property
    def enabled(self) -> bool:
        return self.tolerance_mm > 0

    def observe(self, now_s: float, off_mm: float) -> None:
        """One comparison: the two channels ``off_mm`` apart at ``now_s``."""
        self.off_mm, self.compared_s = off_mm, now_s
        if off_mm <= self.tolerance_mm:
            self._beyond_since = None
        elif self._beyond_since is None:
            self._beyond_since = now_s

    def failing(self, now_s: float) -> Disagreement | None:
        """The disagreement, once it has lasted ``window_s`` and the last comparison is
        recent; None otherwise (no recent comparison is no verdict, not a fault)."""
        if not self.enabled or self._beyond_since is None or self.off_mm is None:
            return None
        if self.compared_s is None or now_s - self.compared_s > self.fresh_s:
            return None
        if now_s - self._beyond_since < self.window_s:
            return None
        return Disagreement(self.channel, self.off_mm, self._beyond_since, self.tolerance_mm,
                            self.remedy)

    def beyond(self) -> bool:
        """The last comparison was beyond the tolerance (however briefly)."""
        return self.enabled and self._beyond_since is not None

    def verdict(self, now_s: float, *, needed: bool = True) -> str | None:
        """Why the gantry may not arm on this channel now: the last recent comparison
        disagrees, or (``needed``) there is none; None when it agrees (or the check is off,
        or no comparison is needed and there is none)."""
        if not self.enabled:
            return None
        if self.compared_s is None or now_s - self.compared_s > self.fresh_s:
            return (f"{self.channel}: no recent comparison with the motion capture "
                    f"({self.remedy})") if needed else None
        if self.off_mm is not None and self.off_mm > self.tolerance_mm:
            return Disagreement(self.channel, self.off_mm, self._beyond_since or now_s,
                                self.tolerance_mm, self.remedy).text(now_s)
        return None
