"""Which marker is the robot, and how fast it moves (pure; times in seconds, positions in mm).

The robot marker is the one with the configured label, or — with no label — the unidentified
marker that keeps moving: a static marker (noise of a millimetre or so) is never taken, and
once a marker is taken it is kept while it is seen, even when the robot stops.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field
from itertools import islice
from typing import NamedTuple, Protocol

import numpy as np

from common.camera import PositionFields
from common.volume import Volume


class Located(PositionFields, Protocol):
    """A marker in one frame: its label ("" if unidentified), its id, and where it is — a
    mocap frame's ``Marker`` as it is (no copy per marker at QTM's rate), or a ``Seen``."""

    @property
    def label(self) -> str: ...
    @property
    def id(self) -> int: ...


class Seen(NamedTuple):
    """A marker made up for the picker: a 6DOF body's origin, or a test's marker."""

    label: str
    id: int
    x_mm: float
    y_mm: float
    z_mm: float

    @classmethod
    def at(cls, label: str, marker_id: int, xyz_mm: Sequence[float] | np.ndarray) -> Seen:
        x, y, z = (float(c) for c in xyz_mm)
        return cls(label, marker_id, x, y, z)


@dataclass
class RobotPicker:
    """Follows the robot through a stream of frames: which marker it is, where it is and how
    fast it moves (the module's docstring has the rule)."""

    label: str = ""
    volume: Volume = Volume()
    motion_window_s: float = 1.0
    min_motion_mm: float = 15.0
    velocity_window_s: float = 0.1
    chosen: int | None = None
    # per marker key: (t, x, y, z) in time order, the last ``motion_window_s`` (plain tuples:
    # at QTM's full rate a frame's work must stay in microseconds)
    _history: dict[int, deque[tuple[float, float, float, float]]] = field(default_factory=dict)
    _slope: SlidingSlope | None = None  # the chosen marker's velocity window
    _slope_key: int | None = None

    def update(self, t_s: float, markers: Sequence[Located]
               ) -> tuple[np.ndarray, np.ndarray] | None:
        """The robot's (position, velocity) in this frame, or None if it is not seen."""
        seen = {self._key(m): xyz for m in markers
                if (m.label == self.label if self.label else not m.label)
                and self.volume.contains(xyz := (m.x_mm, m.y_mm, m.z_mm))}
        for key, (x, y, z) in seen.items():
            history = self._history.setdefault(key, deque())
            history.append((t_s, x, y, z))
            while history and t_s - history[0][0] > self.motion_window_s:
                history.popleft()
        for key in [k for k, h in self._history.items() if t_s - h[-1][0] > self.motion_window_s]:
            del self._history[key]
        if self.chosen not in seen:
            self.chosen = self._pick(seen)
        if self.chosen is None:
            return None
        history = self._history[self.chosen]
        return np.array(history[-1][1:]), self._velocity(history)

    def _key(self, marker: Located) -> int:
        return 0 if self.label else marker.id

    def _pick(self, seen: dict[int, tuple[float, float, float]]) -> int | None:
        if self.label:
            return 0 if 0 in seen else None
        moving = {key: _extent(self._history[key]) for key in seen}
        moving = {key: extent for key, extent in moving.items() if extent > self.min_motion_mm}
        return max(moving, key=moving.__getitem__) if moving else None

    def _velocity(self, history: deque[tuple[float, float, float, float]]) -> np.ndarray:
        """The least-squares slope over the last ``velocity_window_s``; just back from an
        occlusion (fewer than 3 samples in it), over the last 3 samples, bridging it."""
        if self._slope is None or self._slope_key != self.chosen:
            self._slope, self._slope_key = SlidingSlope(self.velocity_window_s), self.chosen
            for sample in history:
                self._slope.push(sample)
        else:
            self._slope.push(history[-1])
        slope = self._slope.slope()
        return slope if slope is not None else _fit(list(islice(reversed(history), 3)))


class SlidingSlope:
    """The least-squares slope of (t, x, y, z) samples over the last ``window_s`` seconds, kept
    by running sums: at QTM's full rate the window holds a hundred samples, and refitting them
    every frame was the tracker's largest cost. Times are taken from a reference moved to the
    newest sample every ``REBASE_EVERY`` pushes (the sums are then summed again), so that the
    sums stay small and subtracting them loses nothing that matters."""

    REBASE_EVERY = 1000

    def __init__(self, window_s: float) -> None:
        self.window_s = window_s
        self.samples: deque[tuple[float, float, float, float]] = deque()
        self._rebase(0.0)

    def push(self, sample: tuple[float, float, float, float]) -> None:
        self.samples.append(sample)
        if self._pushes >= self.REBASE_EVERY or not self._n:
            self._rebase(sample[0])
        else:
            self._add(sample, 1.0)
        while sample[0] - self.samples[0][0] > self.window_s:
            self._add(self.samples.popleft(), -1.0)
        self._pushes += 1

    def slope(self) -> np.ndarray | None:
        """The slope (mm/s per axis), or None with fewer than 3 samples in the window."""
        n = self._n
        if n < 3:
            return None
        denominator = self._stt - self._st * self._st / n
        if denominator <= 1e-12:  # (nearly) equal times: no slope to fit
            return np.zeros(3)
        return np.array([(stp - self._st * sp / n) / denominator
                         for sp, stp in zip(self._sp, self._stp, strict=True)])

    def _rebase(self, t_ref: float) -> None:
        self._t_ref, self._pushes = t_ref, 0
        self._n, self._st, self._stt = 0, 0.0, 0.0
        self._sp, self._stp = [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]
        for sample in self.samples:
            self._add(sample, 1.0)

    def _add(self, sample: tuple[float, float, float, float], sign: float) -> None:
        t = sample[0] - self._t_ref
        self._n += int(sign)
        self._st += sign * t
        self._stt += sign * t * t
        for axis in range(3):
            self._sp[axis] += sign * sample[axis + 1]
            self._stp[axis] += sign * t * sample[axis + 1]


def _fit(samples: list[tuple[float, float, float, float]]) -> np.ndarray:
    """The least-squares slope of a few (t, x, y, z) samples; zero below two."""
    if len(samples) < 2:
        return np.zeros(3)
    array = np.array(samples)
    times = array[:, 0] - array[:, 0].mean()
    denominator = float(times @ times)
    if denominator <= 0:
        return np.zeros(3)
    points = array[:, 1:]
    return times @ (points - points.mean(axis=0)) / denominator


def _extent(history: deque[tuple[float, float, float, float]]) -> float:
    points = np.array(history)[:, 1:]
    return float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))
