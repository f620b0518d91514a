"""Passpoint collection (paper §2.1–2.2), pure: mocap frames and a camera's detections in,
passpoints out.

Passpoints are spread over the picture: one closer than ``min_spacing_px`` to any taken
before is skipped ("seen there"), so that a wand carried back and forth through the middle
does not fill the count there (the lens's distortion is measured at the edges).

The calibration marker is followed in the mocap stream (by label, or as the unlabelled marker
that moves) and kept as a track. A snapshot's detections become a passpoint when exactly one
detected spot can be the marker: spots that stay put while the marker moves (static markers,
reflections, a parked robot) are left out — also a reflection that flickers, at the edge of
the picture or at the threshold, seen at its place in only some of the snapshots. The
marker's position is interpolated from the track at the snapshot's capture time — not "the
next frame", the paper's source of error — and the track itself goes to the solver, which
fits what clock offset remains.

A snapshot is asked for and comes some time later; the camera took it in between. The solver
fits the usual delay (the clock offset); a snapshot answered later than the camera's usual
(a busy machine or network) may have been taken later too, and while the marker moves that is
a passpoint in the wrong place: skipped ("late snapshot") when the marker may have moved more
than ``LATE_MM`` in the extra time.
"""

from __future__ import annotations

from collections import Counter, deque
from dataclasses import dataclass, field

import numpy as np

from common import messages as m
from common.passpoints import Passpoints, Track
from common.robot_picker import RobotPicker

STATIC_WINDOW_S = 4.0
STATIC_SHARE = 0.4  # of the last STATIC_WINDOW_S's snapshots: a flickering reflection is
# there in about half; a wand held still for a passpoint (0.5 s) in an eighth
STATIC_PX = 3.0
MARKER_MOVED_MM = 150.0
MAX_GAP_S = 0.1
LATE_MM = 3.0  # about half a pixel at the widest zoom 4 m away (the AXIS 215's 3.8 mm lens)
USUAL_ANSWERS = 20  # the camera's usual answer: the median of this many snapshots before
SPEED_WINDOW_S = 0.1  # the marker's speed: over this long before the snapshot was asked for


@dataclass
class Collector:
    target: int
    marker_label: str = "wand"
    min_spacing_mm: float = 50.0
    min_spacing_px: float = 0.0
    coverage: tuple[int, int, int] = (0, 0, 0)
    """(columns, rows, passpoints per cell): done only once every cell of that grid over the
    picture holds that many (the lens's distortion is measured in the corners); 0: none"""
    corners: tuple[float, int] = (0.0, 0)
    """(share, passpoints): done only once each corner of the picture — that share of its
    width and of its height from both edges — holds that many; 0: none. A grid cell is large,
    its passpoints may all lie on its inner side; the corners are where the distortion is
    largest and where a fit without passpoints there extrapolates"""
    in_corners: Counter[str] = field(default_factory=Counter)
    cells: Counter[tuple[int, int]] = field(default_factory=Counter)
    picker: RobotPicker = field(init=False)
    track_t: list[float] = field(default_factory=list)
    track_xyz: list[np.ndarray] = field(default_factory=list)
    times: list[float] = field(default_factory=list)
    world: list[np.ndarray] = field(default_factory=list)
    pixels: list[tuple[float, float]] = field(default_factory=list)
    skipped: Counter[str] = field(default_factory=Counter)
    snapshots: int = 0
    _spots: deque[tuple[float, list[tuple[float, float]]]] = field(default_factory=deque)
    _answers: deque[float] = field(default_factory=lambda: deque(maxlen=USUAL_ANSWERS))

    def __post_init__(self) -> None:
        self.picker = RobotPicker(self.marker_label)

    @property
    def done(self) -> bool:
        return len(self.times) >= self.target and not self.uncovered()

    def uncovered(self) -> list[str]:
        """The grid cells and the corners still short of passpoints, by name ("top left",
        "row 2, column 3", "bottom left corner")."""
        columns, rows, need = self.coverage
        cells = [] if need == 0 else [_cell_name(c, r, columns, rows) for r in range(rows)
                                      for c in range(columns) if self.cells[(c, r)] < need]
        _, per_corner = self.corners
        return cells + [f"{name} corner" for name in CORNER_NAMES
                        if per_corner and self.in_corners[name] < per_corner]

    def on_frame(self, frame: m.MarkerFrame) -> None:
        found = self.picker.update(frame.measured_s, frame.markers)
        if found is None or (self.track_t and frame.measured_s <= self.track_t[-1]):
            return
        self.track_t.append(frame.measured_s)
        self.track_xyz.append(found[0])

    def on_detections(self, msg: m.MarkerDetections) -> str | None:
        """Take a snapshot's detections; returns why it gave no passpoint, or None if it did.
        Call it once the mocap stream has passed the snapshot's time (see ``track_covers``)."""
        self.snapshots += 1
        t = msg.measured_s
        spots = [(d.u_px, d.v_px) for d in msg.markers]
        self._spots.append((t, spots))
        while self._spots and t - self._spots[0][0] > STATIC_WINDOW_S:
            self._spots.popleft()
        late_s = self._later_than_usual_s(msg.answered_after_s)
        reason = self._reason(msg, spots, late_s)
        if reason is not None:
            self.skipped[reason] += 1
            return reason
        return None

    def track_covers(self, t: float) -> bool:
        return bool(self.track_t) and self.track_t[-1] >= t

    def passpoints(self) -> Passpoints:
        return Passpoints(np.array(self.world).reshape(-1, 3),
                          np.array(self.pixels, dtype=float).reshape(-1, 2),
                          np.array(self.times, dtype=float))

    def track(self) -> Track:
        return Track(np.array(self.track_t), np.array(self.track_xyz).reshape(-1, 3))

    def _later_than_usual_s(self, answered_after_s: float) -> float:
        """How much later than the camera's usual this snapshot was answered (0: not later,
        not known, or too few snapshots yet to know the usual)."""
        if answered_after_s <= 0:
            return 0.0
        usual = float(np.median(self._answers)) if len(self._answers) >= 5 else answered_after_s
        self._answers.append(answered_after_s)
        return max(answered_after_s - usual, 0.0)

    def _moved_mm(self, t: float, late_s: float, xyz: np.ndarray) -> float:
        """How far the marker, at its speed just before ``t``, goes in ``late_s``."""
        before = self._marker_at(t - SPEED_WINDOW_S)
        if before is None:
            return 0.0
        return float(np.linalg.norm(xyz - before)) / SPEED_WINDOW_S * late_s

    def _reason(self, msg: m.MarkerDetections, spots: list[tuple[float, float]],
                late_s: float) -> str | None:
        if msg.status == "too_many":
            return "too many"
        xyz = self._marker_at(msg.measured_s)
        if xyz is None:
            return "marker not in mocap"
        moving = [s for s in spots if not self._static(s, msg.measured_s)]
        if not moving:
            return "no marker"
        if len(moving) > 1:
            return "too many"
        if late_s > 0 and self._moved_mm(msg.measured_s, late_s, xyz) > LATE_MM:
            return "late snapshot"
        if self.world and np.linalg.norm(xyz - self.world[-1]) < self.min_spacing_mm:
            return "not moved"
        if self.pixels and self.min_spacing_px > 0 and np.min(np.hypot(
                *(np.array(self.pixels) - moving[0]).T)) < self.min_spacing_px:
            return "seen there"
        self.times.append(msg.measured_s)
        self.world.append(xyz)
        self.pixels.append(moving[0])
        columns, rows, _ = self.coverage
        if columns and rows:
            u, v = moving[0]
            self.cells[(min(int(u / msg.width_px * columns), columns - 1),
                        min(int(v / msg.height_px * rows), rows - 1))] += 1
        corner = corner_of(*moving[0], msg.width_px, msg.height_px, self.corners[0])
        if corner is not None:
            self.in_corners[corner] += 1
        return None

    def _marker_at(self, t: float) -> np.ndarray | None:
        """The marker's position at ``t`` from the two mocap samples around it, if close."""
        i = int(np.searchsorted(self.track_t, t))
        if i == 0 or i >= len(self.track_t) or self.track_t[i] - self.track_t[i - 1] > MAX_GAP_S:
            return None
        t0, t1 = self.track_t[i - 1], self.track_t[i]
        a = (t - t0) / (t1 - t0)
        return (1 - a) * self.track_xyz[i - 1] + a * self.track_xyz[i]

    def _static(self, spot: tuple[float, float], t: float) -> bool:
        """A spot seen in the same place in most recent snapshots while the marker moved."""
        recent = [s for ts, s in self._spots if t - ts <= STATIC_WINDOW_S]
        if len(recent) < 5:
            return False
        hits = sum(any(np.hypot(u - spot[0], v - spot[1]) <= STATIC_PX for u, v in s)
                   for s in recent)
        return hits >= STATIC_SHARE * len(recent) and self._marker_moved(t - STATIC_WINDOW_S, t)

    def _marker_moved(self, t0: float, t1: float) -> bool:
        lo, hi = np.searchsorted(self.track_t, [t0, t1])
        if hi - lo < 2:
            return False
        path = np.array(self.track_xyz[lo:hi])
        return float(np.max(np.ptp(path, axis=0))) >= MARKER_MOVED_MM


CORNER_NAMES = ("top left", "top right", "bottom left", "bottom right")


def corner_of(u: float, v: float, width_px: int, height_px: int, share: float) -> str | None:
    """The picture's corner a pixel is in (``share`` of the width and height from the edges)."""
    near_u = "left" if u < share * width_px else "right" if u > (1 - share) * width_px else ""
    near_v = "top" if v < share * height_px else "bottom" if v > (1 - share) * height_px else ""
    return f"{near_v} {near_u}" if near_u and near_v else None


def _cell_name(column: int, row: int, columns: int, rows: int) -> str:
    vertical = "" if rows == 1 else {0: "top", rows - 1: "bottom"}.get(
        row, "middle" if rows == 3 else f"row {row + 1}")
    horizontal = "" if columns == 1 else {0: "left", columns - 1: "right"}.get(
        column, "centre" if columns == 3 else f"column {column + 1}")
    return f"{vertical} {horizontal}".strip()
