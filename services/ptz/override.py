"""Someone else's hand on a following camera (pure): a move that did not come from us pauses
following for a while, as Frigate's autotracker does on a manual move.

Our commands send the camera along a path: from each command to the next it moves both axes
at their own speed, so it stays within the box the two commands span. A camera found farther
than ``tolerance_deg`` outside every such box of the last ``window_s`` (and the command in
force before) was moved by someone else: following pauses for ``pause_s``, longer while the
camera keeps moving. ``pause_s`` = 0 never pauses.

Every move the service sends is ours, not only following's: a calibration-mode hold is a
command too (``own_move``), kept for ``own_move_s`` — long enough for the slowest turn —
so that a camera still on its way to a hold, or carrying out a hold queued behind its
latency, is on our path after calibration mode ends; a move to the camera's home (where,
we do not know) is not judged for ``own_move_s``. A camera that stopped answering is judged
afresh when it answers again: a reboot sends it home, which is no one's hand.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field


@dataclass
class ManualOverride:
    tolerance_deg: float = 5.0
    pause_s: float = 30.0
    window_s: float = 1.0
    still_deg: float = 0.5  # moves below this between two looks are not someone's hand
    own_move_s: float = 5.0  # a hold or home move: how long the camera may take (180° at 40°/s)
    paused_until: float = 0.0
    # (until when it counts, pan, tilt) of each command; the first: where the camera was
    _commands: deque[tuple[float, float, float]] = field(default_factory=deque)
    _last_seen: tuple[float, float] | None = None
    _blind_until: float = 0.0  # a move to an unknown place (home) is under way

    def commanded(self, now: float, pan_deg: float, tilt_deg: float,
                  lasts_s: float | None = None) -> None:
        """We sent the camera here (from where it was last seen; unseen yet: no judging); the
        move counts as ours for ``lasts_s`` (default ``window_s``)."""
        if not self._commands:
            if self._last_seen is None:
                return
            self._commands.append((now + self.window_s, *self._last_seen))
        until = now + (self.window_s if lasts_s is None else lasts_s)
        self._commands.append((until, pan_deg, tilt_deg))
        while len(self._commands) > 2 and self._commands[1][0] < now:
            self._commands.popleft()  # keep the one in force before the oldest that counts

    def own_move(self, now: float, pan_deg: float | None, tilt_deg: float | None) -> None:
        """We moved the camera outside following (calibration mode): to ``pan_deg``,
        ``tilt_deg``, or — either unknown (home) — somewhere we cannot judge for a while."""
        self.paused_until = 0.0  # our move ends anyone's pause
        if pan_deg is None or tilt_deg is None:
            self._commands.clear()
            self._blind_until = now + self.own_move_s
            return
        self.commanded(now, pan_deg, tilt_deg, self.own_move_s)

    def forget(self) -> None:
        """The camera was moved by an operator's hand: no pause, no reference."""
        self._commands.clear()
        self._last_seen, self.paused_until, self._blind_until = None, 0.0, 0.0

    def lost_sight(self) -> None:
        """The camera did not answer (a reboot, a cable): where it is next is no one's hand —
        no reference until we command it again; a pause under way goes on."""
        self._commands.clear()
        self._last_seen, self._blind_until = None, 0.0

    def watch_only(self, pan_deg: float, tilt_deg: float) -> None:
        """Where the camera is while not following (calibration mode holds it): seen, not
        judged; no pause."""
        self._last_seen, self.paused_until = (pan_deg, tilt_deg), 0.0

    def paused(self, now: float) -> bool:
        return now < self.paused_until

    def observe(self, now: float, pan_deg: float, tilt_deg: float) -> bool:
        """Where the camera is now; True when this look started (or extended) a pause."""
        moved = self._last_seen is not None and max(
            abs(pan_deg - self._last_seen[0]), abs(tilt_deg - self._last_seen[1])) > self.still_deg
        self._last_seen = (pan_deg, tilt_deg)
        if self.pause_s <= 0 or now < self._blind_until:
            return False
        if self.paused(now):
            if moved:  # still in someone's hands
                self.paused_until = now + self.pause_s
            return moved
        if not self._commands or self._on_our_path(pan_deg, tilt_deg):
            return False
        self.paused_until = now + self.pause_s
        self._commands.clear()  # what we sent before is no reference after the pause
        return True

    def _on_our_path(self, pan: float, tilt: float) -> bool:
        points = list(self._commands)
        pairs = list(zip(points, points[1:], strict=False)) or [(points[0], points[0])]
        margin = self.tolerance_deg
        return any(min(a[1], b[1]) - margin <= pan <= max(a[1], b[1]) + margin
                   and min(a[2], b[2]) - margin <= tilt <= max(a[2], b[2]) + margin
                   for a, b in pairs)
