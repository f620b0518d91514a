"""The person who carries the calibration wand (paper §2.2) while the robot waits (pure; the
time is an argument).

A lab engineer waves the wand where the camera being calibrated looks, watching its live
picture: at a long zoom that is a patch of a few hundred millimetres, which a wand carried
about the crater at random would almost never cross. So the carrier walks the wand to a point
in the picture of a camera that is being calibrated — the IR-cut filter off and the head
standing still, what calibration mode does to a camera — at that camera's present zoom, holds
it still for ``dwell_s``, and on to the next; taking turns when several are. With no camera
in calibration mode it walks to points over the crater (``wander``), as before. A share of the
points is in the picture's corners, as lens calibration guides ask of a person, who goes round
them in turn (not by dice: a corner left out for minutes held a collection up).

The picture is the camera's own (its true lens, ``views``): the carrier uses the sim's truth
only as a person uses what they see. Points are spread over the whole picture, corners
included (where the lens bends most), at depths from near to the ground.
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from common.camera import Intrinsics, Pose, undistort_pixels

EDGE_MARGIN = 0.015  # of the picture's width and height kept clear of the border (≈ 10 px)
CORNERS = 0.4  # of the points: in a corner of the picture
CORNER_SIZE = 0.12  # a corner: this share of the picture's width and of its height
NEAREST_MM = 800.0  # no nearer to the camera than this (a person holds it at arm's length)
ABOVE_GROUND_MM = 150.0  # a point on the wand's pole stays this high over the floor
FARTHEST_MM = 9000.0
SEGMENTS_KEPT = 64  # enough for any look back (exposure smear, a late mocap frame)

View = tuple[Pose, Intrinsics]


@dataclass(frozen=True)
class _Segment:
    start: np.ndarray
    end: np.ndarray
    depart_s: float
    arrive_s: float
    leave_s: float


@dataclass
class WandCarrier:
    rng: np.random.Generator
    wander: Callable[[np.random.Generator], np.ndarray]
    """a point over the crater to walk to when no camera is being calibrated"""
    views: Callable[[float], list[View]]
    """the cameras in calibration mode at a time: where each looks from, through which lens"""
    ground_mm: Callable[[float, float], float]
    start_mm: np.ndarray
    speed_mm_s: float = 600.0
    dwell_s: float = 0.5
    _segments: deque[_Segment] = field(default_factory=lambda: deque(maxlen=SEGMENTS_KEPT))
    _turn: int = 0
    _corner: int = 0
    _lock: threading.Lock = field(default_factory=threading.Lock)

    def position(self, t: float) -> np.ndarray:
        segment = self._segment(t)
        if t >= segment.arrive_s or segment.arrive_s <= segment.depart_s:
            return segment.end.copy()
        if t <= segment.depart_s:
            return segment.start.copy()
        f = (t - segment.depart_s) / (segment.arrive_s - segment.depart_s)
        return segment.start + f * (segment.end - segment.start)

    def velocity(self, t: float) -> np.ndarray:
        segment = self._segment(t)
        if not segment.depart_s < t < segment.arrive_s:
            return np.zeros(3)
        return (segment.end - segment.start) / (segment.arrive_s - segment.depart_s)

    def _segment(self, t: float) -> _Segment:
        with self._lock:
            if not self._segments:
                start = np.asarray(self.start_mm, dtype=float)
                self._segments.append(_Segment(start, start, t, t, t + self.dwell_s))
            while self._segments[-1].leave_s <= t:
                self._segments.append(self._next(self._segments[-1]))
            for segment in reversed(self._segments):
                if segment.depart_s <= t:
                    return segment
            return self._segments[0]

    def _next(self, last: _Segment) -> _Segment:
        now = last.leave_s
        views = self.views(now)
        target = None
        if views:
            target = self.in_view(*views[self._turn % len(views)])
            self._turn += 1
        if target is None:
            target = np.asarray(self.wander(self.rng), dtype=float)
        travel = float(np.linalg.norm(target - last.end)) / self.speed_mm_s
        return _Segment(last.end, target, now, now + travel, now + travel + self.dwell_s)

    def in_view(self, pose: Pose, intr: Intrinsics, tries: int = 20) -> np.ndarray | None:
        """A point the camera sees at a random place in its picture, between ``NEAREST_MM``
        and the floor; None when none was found (a camera looking at the sky)."""
        corner = self.rng.random() < CORNERS
        for _ in range(tries):
            u, v = self._spot(corner) * (intr.width_px, intr.height_px)
            straight = undistort_pixels(np.array([[u, v]]), intr)[0]
            ray = pose.rotation @ np.array([1.0, (straight[0] - intr.cy_px) / intr.fy_px,
                                            (straight[1] - intr.cz_px) / intr.fz_px])
            ray /= np.linalg.norm(ray)
            reach = self._reach(pose.position, ray)
            if reach > NEAREST_MM:
                self._corner += corner  # that corner done: the next one next time
                return pose.position + ray * self.rng.uniform(NEAREST_MM, reach)
        return None

    def _spot(self, corner: bool) -> np.ndarray:
        """Where in the picture (fractions of its width and height): anywhere, or — as lens
        calibration guides ask, the lens bending most there — in a corner (``CORNERS`` of the
        points), the four in turn."""
        if not corner:
            return self.rng.uniform(EDGE_MARGIN, 1 - EDGE_MARGIN, 2)
        near = self.rng.uniform(EDGE_MARGIN, CORNER_SIZE, 2)
        right, low = self._corner % 2, (self._corner // 2) % 2
        return np.where(np.array([right, low]) == 1, 1 - near, near)

    def _reach(self, origin: np.ndarray, ray: np.ndarray) -> float:
        """How far along the ray the wand may go before it comes too near the floor."""
        step = 100.0
        distance = NEAREST_MM
        while distance < FARTHEST_MM:
            x, y, z = origin + ray * distance
            if z < self.ground_mm(x, y) + ABOVE_GROUND_MM:
                return distance - step
            distance += step
        return FARTHEST_MM
