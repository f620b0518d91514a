"""The sim's time, shared by its processes."""

from __future__ import annotations

import time
from collections.abc import Callable


class Clock:
    """Sim time: seconds since start (monotonic), and the wall time of a sim instant.

    ``t0_monotonic`` lets several processes share one sim time (monotonic time is
    system-wide). The wall time of an instant is read from the wall clock when asked, as a
    device whose clock is kept by NTP stamps what it captures: a host whose wall clock is
    stepped or slewed against its monotonic one (seen on a CI machine: ≈ 5 s, then 2 000–5 000
    ppm for minutes) would otherwise see the sim's stamps off its own by seconds."""

    def __init__(self, t0_monotonic: float | None = None, *,
                 monotonic: Callable[[], float] = time.monotonic,
                 wall_clock: Callable[[], float] = time.time) -> None:
        self._monotonic, self._wall_clock = monotonic, wall_clock
        self.t0_monotonic = monotonic() if t0_monotonic is None else t0_monotonic

    def __call__(self) -> float:
        return self._monotonic() - self.t0_monotonic

    def wall(self, t: float) -> float:
        return self._wall_clock() - (self() - t)
