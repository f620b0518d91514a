"""The rules of one passpoint collection, on a clock it is given: no bus, no thread, no sleep.

At several zoom steps (``zooms``), the camera is held at each in turn: ``count`` passpoints
at the widest (and its picture covered, corners included: the distortion is measured there),
``step_count`` at each of the others (a focal length; fewer do: docs/calibration.md); a
zoom's passpoints count only from the camera's first state at that zoom (the zoom has
arrived). Detections wait until the mocap stream has passed their capture time
(at most ``MOCAP_WAIT_S``), so that the marker's position is interpolated, never extrapolated.

The session (``session.py``) feeds it what the bus brings and calls ``step(now)`` every tick;
``step`` answers with what to do: hold the camera (again), publish progress, keep an image of a
passpoint just taken, and at the end: collected (solve now) or ended (failed, cancelled).
"""

from __future__ import annotations

import logging
from collections import Counter, deque
from dataclasses import dataclass

import numpy as np

from common import messages as m
from common.data_sheet import AXIS_215_PICTURE_PX
from common.passpoint_collector import Collector
from services.calib.settings import CalibSettings

log = logging.getLogger(__name__)
PROGRESS_S = 0.5
MOCAP_WAIT_S = 1.0
WIDE_COVERAGE = (4, 3, 3)  # at the widest of several zooms: every cell of a 4×3 grid, 3 each
WIDE_CORNERS = (0.15, 3)  # and each corner (15 % of width and height from the edges), 3 each
STALL_HINTS = {  # why snapshots gave no passpoint → what to check
    "no marker": "the wand is not in the camera's view (or the IR cut filter is on)",
    "too many": "more bright spots than the wand (reflections, markers)",
    "not moved": "the wand does not move",
    "seen there": "the wand stays where passpoints were taken: carry it to the rest of the "
                  "picture (edges and corners)",
    "late snapshot": "the camera answered late (a busy machine or network) while the wand "
                     "moved: carry it more slowly, or hold it still a moment at each spot",
    "marker not in mocap": "the motion capture does not see the wand (is the tracker "
                           "streaming? is the marker label right?)",
}


@dataclass(frozen=True)
class HoldCamera:
    """Put (or keep) the camera in calibration mode at this zoom (None: the hold's own)."""

    zoom: int | None


@dataclass(frozen=True)
class PublishProgress:
    """Tell the page and the CLI how far the collection is."""


@dataclass(frozen=True)
class KeepImage:
    """A passpoint was just taken from these detections: keep its picture, annotated."""

    detections: m.MarkerDetections
    index: int  # over every zoom's passpoints
    pixel: tuple[float, float]  # the spot taken


@dataclass(frozen=True)
class Collected:
    """Every zoom has its passpoints: solve."""


@dataclass(frozen=True)
class Ended:
    """The collection ended without passpoints enough."""

    state: m.CollectState  # "failed" or "cancelled"
    message: str


Action = HoldCamera | PublishProgress | KeepImage | Collected | Ended


@dataclass
class _Gained:
    """The last time the passpoint count grew, and what had been skipped by then."""

    passpoints: int
    at_s: float
    skipped: Counter[str]


class Collection:
    """One camera's collection rules; ``started_s`` is the time it started, on the clock
    ``step`` is given and detections and states are stamped with."""

    def __init__(self, settings: CalibSettings, camera: str, count: int, timeout_s: float,
                 zooms: list[int] | None, started_s: float, step_count: int | None = None
                 ) -> None:
        self.settings, self.camera = settings, camera
        self.timeout_s, self.started_s = timeout_s, started_s
        self.zooms = list(zooms or [])
        track_t: list[float] = []  # one mocap track for every zoom's collector
        track_xyz: list[np.ndarray] = []
        each: list[int | None] = list(self.zooms) if self.zooms else [None]  # None: as it is
        widest = min(self.zooms) if self.zooms else None
        at_step = min(count, step_count or count)
        self.collectors = [Collector(count if zoom == widest else at_step,
                                     settings.marker_label, settings.min_spacing_mm,
                                     settings.min_spacing_px, track_t=track_t,
                                     track_xyz=track_xyz)
                           for zoom in each]
        if self.zooms:  # the lens's distortion is measured at the widest step
            wide = self.collectors[each.index(widest)]
            wide.coverage, wide.corners = WIDE_COVERAGE, WIDE_CORNERS
        self.collector = self.collectors[0]
        self.picture_px = AXIS_215_PICTURE_PX  # the snapshots' size, as their detections say
        self._zoom_index = 0
        self._zoom_since: float | None = None  # the camera's first state at the present zoom
        self._pending: deque[m.MarkerDetections] = deque(maxlen=200)
        self._camera_state: m.PtzState | None = None
        self._holding = True  # the camera is held for the collection: its states count
        self._held = False  # the PTZ service has answered the hold at this zoom
        self._cancelled = False
        self._over = False
        self._gained = _Gained(0, started_s, Counter(self.collector.skipped))
        self._renew_at_s = self._progress_at_s = float("-inf")

    # --- what the bus brings -----------------------------------------------------------------

    def on_frame(self, msg: m.MarkerFrame) -> None:
        self.collector.on_frame(msg)

    def on_detections(self, msg: m.MarkerDetections) -> None:
        if msg.measured_s >= self.started_s:
            self._pending.append(msg)
            self.picture_px = (msg.width_px, msg.height_px)

    def on_state(self, msg: m.PtzState) -> None:
        if self._holding and msg.status == "calibrating" and msg.measured_s >= self.started_s:
            if self.zoom is not None and msg.zoom != self.zoom:
                return  # still zooming to the step (or not there yet)
            if self._zoom_since is None:
                self._zoom_since = msg.measured_s
            self._camera_state = msg

    def stop_holding(self) -> None:
        """The collection is over: a state that comes after the camera is released (it may
        still say "calibrating" while it turns back home) is not the passpoints' pan and
        tilt."""
        self._holding = False

    def cancel(self) -> None:
        self._cancelled = True

    # --- what it knows -----------------------------------------------------------------------

    @property
    def zoom(self) -> int | None:
        """The zoom step being collected at (None: one zoom, the hold's)."""
        return self.zooms[self._zoom_index] if self.zooms else None

    @property
    def camera_state(self) -> m.PtzState | None:
        """The camera as it reported itself while held for the collection (its pan and tilt
        are the passpoints')."""
        return self._camera_state

    def progress(self, now: float, state: m.CollectState, message: str,
                 mean_error_px: float | None) -> m.CollectProgress:
        c = self.collector
        return m.CollectProgress(
            measured_s=now, camera=self.camera, state=state,
            passpoints=sum(len(k.times) for k in self.collectors),
            target=sum(k.target for k in self.collectors), snapshots=c.snapshots,
            skipped=dict(c.skipped),
            message=m.text(message or (self._coverage_text() if state == "collecting" else "")),
            mean_error_px=mean_error_px, zoom=self.zoom,
            zooms_done=sum(k.done for k in self.collectors), zooms=len(self.zooms))

    # --- the clock ---------------------------------------------------------------------------

    def step(self, now: float) -> list[Action]:
        """What to do at ``now``; nothing more once collected or ended."""
        if self._over:
            return []
        if not self._held and self._camera_state is not None:
            # the stall clock starts again when the PTZ service holds the camera: a
            # collection may start before that service is up, or while the camera turns
            self._held = True
            self._gained = _Gained(self._gained.passpoints, now, self._gained.skipped)
        if self._cancelled:
            return self._end("cancelled", "cancelled")
        if now > self.started_s + self.timeout_s:
            return self._end("failed", f"timed out after {self.timeout_s:g} s with "
                             f"{len(self.collector.times)} of {self.collector.target} "
                             f"passpoints{self._zoom_text()} ({self._skipped_text()})")
        if len(self.collector.times) != self._gained.passpoints:
            self._gained = _Gained(len(self.collector.times), now, Counter(self.collector.skipped))
        elif now - self._gained.at_s > (stall := self._stall_s()):
            return self._end("failed", self._stalled_text(self._gained.skipped, stall))
        actions: list[Action] = []
        if now >= self._renew_at_s:
            actions.append(HoldCamera(self.zoom))
            self._renew_at_s = now + self.settings.lease_s / 3
        actions.extend(self._take_pending(now))
        if self.collector.done:
            if self._zoom_index + 1 >= len(self.collectors):
                self._over = True
                return [*actions, Collected()]
            self._next_zoom(now)
        if now >= self._progress_at_s:
            actions.append(PublishProgress())
            self._progress_at_s = now + PROGRESS_S
        return actions

    def _stall_s(self) -> float:
        s = self.settings
        return s.stall_s if self._held else max(s.stall_s, s.hold_wait_s)

    def _end(self, state: m.CollectState, message: str) -> list[Action]:
        self._over = True
        return [Ended(state, message)]

    def _next_zoom(self, now: float) -> None:
        """The present zoom has its passpoints: on to the next step (the camera is held there
        by the next renewal, at once; its passpoints count once it reports that zoom)."""
        self._zoom_index += 1
        self.collector = self.collectors[self._zoom_index]
        self._camera_state, self._zoom_since, self._held = None, None, False
        self._pending.clear()
        self._renew_at_s = float("-inf")
        self._gained = _Gained(0, now, Counter(self.collector.skipped))
        log.info("%s: passpoints at zoom %d (%d of %d)", self.camera, self.zoom,
                 self._zoom_index + 1, len(self.zooms))

    def _take_pending(self, now: float) -> list[Action]:
        kept: list[Action] = []
        while self._pending:
            msg = self._pending[0]
            if self.zooms and (self._zoom_since is None or msg.measured_s < self._zoom_since):
                self._pending.popleft()  # taken before the camera stood at this zoom
                continue
            if not self.collector.track_covers(msg.measured_s) and \
                    now - msg.measured_s < MOCAP_WAIT_S:
                break
            self._pending.popleft()
            if self.collector.done:
                continue
            if self.collector.on_detections(msg) is None:
                index = sum(len(c.times) for c in self.collectors) - 1
                u, v = self.collector.pixels[-1]
                kept.append(KeepImage(msg, index, (float(u), float(v))))
        return kept

    # --- what it says ------------------------------------------------------------------------

    def _stalled_text(self, skipped_before: Counter[str], stall_s: float) -> str:
        since = self.collector.skipped - skipped_before
        seen = ", ".join(f"{n} {why}" for why, n in since.most_common()) or "no snapshot at all"
        # a hint for every reason seen, the most frequent first (a slow start can give more
        # snapshots before the mocap stream than after it: the camera's view must still show)
        hints = [STALL_HINTS[why] for why, _ in since.most_common() if why in STALL_HINTS] \
            if since else ["the PTZ service sends no detections (is the camera still?)"
                           if self._camera_state is not None else
                           "the PTZ service has not taken the camera into calibration mode "
                           "(is it running?)"]
        return (f"no passpoint for {stall_s:g} s ({len(self.collector.times)} of "
                f"{self.collector.target}; since the last: {seen})"
                + (f": {'; '.join(hints)}" if hints else ""))

    def _coverage_text(self) -> str:
        missing = self.collector.uncovered()
        return f"carry the wand to the picture's {', '.join(missing)}" if missing else ""

    def _zoom_text(self) -> str:
        if not self.zooms:
            return ""
        return f" at zoom {self.zoom} (step {self._zoom_index + 1} of {len(self.zooms)})"

    def _skipped_text(self) -> str:
        skipped = self.collector.skipped
        return ", ".join(f"{n} {why}" for why, n in skipped.most_common()) or "none skipped"
