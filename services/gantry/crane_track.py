"""Where the crane was at any recent moment, from its controller's reports (pure).

Eq. 8 adds the marker's offset in the tracking camera's picture to the crane's position — the
crane's position *when the picture was taken*. The controller reports its position (and
velocity) once per cycle, measured ``report_age_s`` before it reports it, so the gantry keeps
the recent reports with the times they were measured and asks for the crane at a picture's
capture time: between two reports the crane's path is the cubic through both positions with
both velocities (Hermite); after the newest it is carried on with the newest velocity and the
last two reports' acceleration, and how far it was carried is said
(``Paired.extrapolated_s``), so that the caller can trust it less or not at all. Adding a
stale picture's offset to the crane's current position instead made the gantry swing
±35–75 mm around a robot standing still (the estimate ran ahead by the crane's speed times
the picture's age).
"""

from __future__ import annotations

from bisect import bisect_right
from collections import deque
from dataclasses import dataclass

import numpy as np

KEEP_S = 2.0
"""Reports kept this long (a picture is never older than the bus lets it be: 0.5 s)."""


@dataclass(frozen=True)
class Report:
    """One report: measured at ``t_s`` (the frames' clock), position and velocity (mm, mm/s,
    the world's axes)."""

    t_s: float
    xy_mm: np.ndarray
    v_mm_s: np.ndarray


@dataclass(frozen=True)
class Paired:
    """The crane at a moment: where, and how far beyond the newest report it was carried on
    with that report's velocity (0: between two reports)."""

    xy_mm: np.ndarray
    extrapolated_s: float
    v_mm_s: np.ndarray  # its velocity then (the nearer report's)


class CraneTrack:
    """The crane's recent reports, and its position at any moment they cover."""

    def __init__(self, keep_s: float = KEEP_S) -> None:
        self.keep_s = keep_s
        self._reports: deque[Report] = deque()

    def add(self, t_s: float, xy_mm: np.ndarray, v_mm_s: np.ndarray) -> None:
        """A report measured at ``t_s``; one measured no later than the newest is not news."""
        if self._reports and t_s <= self._reports[-1].t_s:
            return
        self._reports.append(Report(t_s, np.array(xy_mm, dtype=float),
                                    np.array(v_mm_s, dtype=float)))
        while self._reports[0].t_s < t_s - self.keep_s:
            self._reports.popleft()

    def forget(self) -> None:
        """The crane moved without reporting (link lost, stopped on its own): start afresh."""
        self._reports.clear()

    @property
    def newest(self) -> Report | None:
        return self._reports[-1] if self._reports else None

    def at(self, t_s: float) -> Paired | None:
        """The crane at ``t_s``, or None with no report yet. Before the oldest report kept it
        is carried back with that report's velocity (flagged the same way)."""
        if not self._reports:
            return None
        newest, oldest = self._reports[-1], self._reports[0]
        if t_s >= newest.t_s:
            dt = t_s - newest.t_s
            accel = np.zeros(2) if len(self._reports) < 2 else (
                newest.v_mm_s - self._reports[-2].v_mm_s) / (newest.t_s - self._reports[-2].t_s)
            return Paired(newest.xy_mm + newest.v_mm_s * dt + 0.5 * accel * dt * dt, dt,
                          newest.v_mm_s + accel * dt)
        if t_s <= oldest.t_s:
            return Paired(oldest.xy_mm + oldest.v_mm_s * (t_s - oldest.t_s), oldest.t_s - t_s,
                          oldest.v_mm_s)
        after = next(i for i, r in enumerate(self._reports) if r.t_s > t_s)
        a, b = self._reports[after - 1], self._reports[after]
        nearer = a if t_s - a.t_s < b.t_s - t_s else b
        return Paired(hermite(a, b, t_s), 0.0, nearer.v_mm_s)


class MarkerTrack:
    """The motion capture's marker on the crane's carriage, sampled as it comes (its own
    capture times, exact to the motion capture's clock): where the crane was, to a millimetre,
    between two samples. The controller's reports are only roughly timed (their age varies by
    tens of milliseconds, ``report_spread_s``); where the motion capture sees the carriage, the
    frames are paired with it instead."""

    def __init__(self, keep_s: float = KEEP_S, max_gap_s: float = 0.1) -> None:
        self.keep_s, self.max_gap_s = keep_s, max_gap_s
        self._t: deque[float] = deque()
        self._xy: deque[np.ndarray] = deque()

    def add(self, t_s: float, xy_mm: np.ndarray) -> None:
        if self._t and t_s <= self._t[-1]:
            return
        self._t.append(t_s)
        self._xy.append(np.array(xy_mm, dtype=float))
        while self._t[0] < t_s - self.keep_s:
            self._t.popleft()
            self._xy.popleft()

    @property
    def newest_s(self) -> float | None:
        """When the marker was seen last."""
        return self._t[-1] if self._t else None

    def at(self, t_s: float, *, ahead_s: float) -> Paired | None:
        """The carriage at ``t_s`` between two samples at most ``max_gap_s`` apart, or after
        the newest by at most ``ahead_s`` (carried on with the last two samples' velocity);
        None otherwise (the marker not seen then, or not yet)."""
        if len(self._t) < 2 or t_s < self._t[0] or t_s > self._t[-1] + ahead_s:
            return None
        after = min(bisect_right(self._t, t_s), len(self._t) - 1)
        t0, t1 = self._t[after - 1], self._t[after]
        if t1 - t0 > self.max_gap_s:
            return None
        v = (self._xy[after] - self._xy[after - 1]) / (t1 - t0)
        return Paired(self._xy[after - 1] + v * (t_s - t0), max(0.0, t_s - self._t[-1]), v)


def hermite(a: Report, b: Report, t_s: float) -> np.ndarray:
    """The cubic through ``a`` and ``b`` with their velocities, at ``t_s`` between them."""
    h = b.t_s - a.t_s
    s = (t_s - a.t_s) / h
    s2, s3 = s * s, s * s * s
    return ((2 * s3 - 3 * s2 + 1) * a.xy_mm + (s3 - 2 * s2 + s) * h * a.v_mm_s
            + (-2 * s3 + 3 * s2) * b.xy_mm + (s3 - s2) * h * b.v_mm_s)
