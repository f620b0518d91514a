"""The sim's time, shared by its processes."""

from __future__ import annotations

import time


class Clock:
    """Sim time: seconds since start (monotonic), and the wall time of a sim instant.

    ``t0_monotonic`` lets several processes share one sim time (monotonic time is
    system-wide)."""

    def __init__(self, t0_monotonic: float | None = None) -> None:
        now_mono, now_wall = time.monotonic(), time.time()
        self.t0_monotonic = now_mono if t0_monotonic is None else t0_monotonic
        self._wall0 = now_wall - (now_mono - self.t0_monotonic)

    def __call__(self) -> float:
        return time.monotonic() - self.t0_monotonic

    def wall(self, t: float) -> float:
        return self._wall0 + t
