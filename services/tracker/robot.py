"""Which marker is the robot, and how fast it moves (pure; times in seconds, positions in mm).

The robot marker is the one with the configured label, or — with no label — the unidentified
marker that keeps moving: a static marker (noise of a millimetre or so) is never taken, and
once a marker is taken it is kept while it is seen, even when the robot stops.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np

from common.volume import Volume


@dataclass(frozen=True)
class Seen:
    """A marker in one frame: its label ("" if unidentified), its id, and where it is."""

    label: str
    id: int
    xyz_mm: np.ndarray


@dataclass
class RobotPicker:
    label: str = ""
    volume: Volume = Volume()
    motion_window_s: float = 1.0
    min_motion_mm: float = 15.0
    velocity_window_s: float = 0.1
    chosen: int | None = None
    _history: dict[int, deque[tuple[float, np.ndarray]]] = field(default_factory=dict)

    def update(self, t_s: float, markers: list[Seen]) -> tuple[np.ndarray, np.ndarray] | None:
        """The robot's (position, velocity) in this frame, or None if it is not seen."""
        seen = {self._key(m): m.xyz_mm for m in markers
                if self.volume.contains(m.xyz_mm) and (m.label == self.label if self.label
                                                      else not m.label)}
        for key, xyz in seen.items():
            history = self._history.setdefault(key, deque())
            history.append((t_s, xyz))
            while history and t_s - history[0][0] > self.motion_window_s:
                history.popleft()
        for key in [k for k, h in self._history.items() if t_s - h[-1][0] > self.motion_window_s]:
            del self._history[key]
        if self.chosen not in seen:
            self.chosen = self._pick(seen)
        if self.chosen is None:
            return None
        return seen[self.chosen], self._velocity(self._history[self.chosen], t_s)

    def _key(self, marker: Seen) -> int:
        return 0 if self.label else marker.id

    def _pick(self, seen: dict[int, np.ndarray]) -> int | None:
        if self.label:
            return 0 if 0 in seen else None
        moving = {key: _extent(self._history[key]) for key in seen}
        moving = {key: extent for key, extent in moving.items() if extent > self.min_motion_mm}
        return max(moving, key=moving.__getitem__) if moving else None

    def _velocity(self, history: deque[tuple[float, np.ndarray]], t_s: float) -> np.ndarray:
        recent = [(t, p) for t, p in history if t_s - t <= self.velocity_window_s]
        if len(recent) < 3:  # just back from an occlusion: bridge it with older samples
            recent = [(t, p) for t, p in history if t_s - t <= self.motion_window_s][-3:]
        if len(recent) < 2:
            return np.zeros(3)
        times = np.array([t for t, _ in recent])
        points = np.array([p for _, p in recent])
        times = times - times.mean()
        denominator = float(times @ times)
        if denominator <= 0:
            return np.zeros(3)
        return times @ (points - points.mean(axis=0)) / denominator  # least-squares slope


def _extent(history: deque[tuple[float, np.ndarray]]) -> float:
    points = np.array([p for _, p in history])
    return float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))
