"""The calib service's rules about poses (pure: no bus, no timers, the time is given): which
version a new solve gets, whether a pose heard on the bus is its own, how long a pose it did
not send keeps its health degraded, and what its health says."""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable, Mapping

from common import messages as m

FOREIGN_REPORTED_S = 60.0  # health is degraded this long after the last foreign pose


def next_version(pose: m.CameraPose, held: m.CameraPose | None) -> m.CameraPose:
    """A new solve as stored: one version above the pose held for its camera (1 if none)."""
    return pose.model_copy(update={"version": (held.version if held else 0) + 1})


def same_solve(a: m.CameraPose, b: m.CameraPose) -> bool:
    """The same pose whatever its version and publication time (an echo or a re-assertion)."""
    ignore = {"version", "sent_s"}
    return a.model_dump(exclude=ignore) == b.model_dump(exclude=ignore)


def rotation_gap_deg(a: m.CameraPose, b: m.CameraPose) -> float:
    """The largest difference of the two poses' rotation angles, degrees in ±180."""
    return max(abs((getattr(a, f) - getattr(b, f) + 180) % 360 - 180)
               for f in ("rx_deg", "ry_deg", "rz_deg"))


class ForeignPoses:
    """When poses it did not send were heard, per camera, for the last ``window_s``."""

    def __init__(self, window_s: float = FOREIGN_REPORTED_S, keep: int = 10_000) -> None:
        self.window_s, self.keep = window_s, keep
        self._heard: dict[str, deque[float]] = {}

    def heard(self, camera: str, now_s: float) -> bool:
        """One more; True if it is the first one in the window (worth a log line)."""
        times = self._heard.setdefault(camera, deque(maxlen=self.keep))
        self._forget(times, now_s)
        times.append(now_s)
        return len(times) == 1

    def counts(self, now_s: float) -> dict[str, int]:
        """How many each camera had in the window up to ``now_s``."""
        for times in self._heard.values():
            self._forget(times, now_s)
        return {camera: len(times) for camera, times in self._heard.items() if times}

    def next_change_s(self) -> float | None:
        """When the oldest in the window leaves it (the health must be looked at again then);
        None when the window is empty."""
        oldest = [times[0] for times in self._heard.values() if times]
        return min(oldest) + self.window_s if oldest else None

    def _forget(self, times: deque[float], now_s: float) -> None:
        while times and now_s - times[0] >= self.window_s:
            times.popleft()


def health(cameras: Iterable[str], poses: Mapping[str, m.CameraPose],
           foreign: Mapping[str, int]) -> tuple[m.HealthStatus, str]:
    """Degraded while a camera has no pose, or poses it did not send were heard lately."""
    missing = [c for c in cameras if c not in poses]
    problems = [f"no pose yet: {', '.join(missing)}"] if missing else []
    problems += [f"{c}: {n} poses it did not send were on the bus in the last minute "
                 "(not taken: PTZ services ask this service)"
                 for c, n in sorted(foreign.items()) if n]
    return ("degraded" if problems else "ok"), "; ".join(problems)
