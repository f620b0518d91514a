"""One passpoint collection for one camera: calibration mode on, passpoints in, pose out.

At several zoom steps (``zooms``), the camera is held at each in turn and ``count`` passpoints
are taken at each; a zoom's passpoints count only from the camera's first state at that zoom
(the zoom has arrived); one fit then gives the pose and the lens (``zoom_fit.py``).

Runs in its own thread; the bus handlers hand it mocap frames, detections, snapshots and
camera states. Detections wait until the mocap stream has passed their capture time, so that
the marker's position is interpolated, never extrapolated.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter, OrderedDict, deque
from collections.abc import Callable

import cv2
import numpy as np

from common import keys
from common import messages as m
from common.camera import mount_pose
from common.jpeg import JpegError, decode_gray
from common.markers import Detection, annotate, marker_of
from common.node import Node
from common.passpoint_collector import Collector
from common.passpoints import CalibrationError, Passpoints
from services.calib.options import Options
from services.calib.settings import CalibSettings
from services.calib.store import PoseStore
from services.calib.worker import in_worker, solve_one_zoom, solve_zooms_and_plot

log = logging.getLogger(__name__)
TICK_S = 0.05
PROGRESS_S = 0.5
MOCAP_WAIT_S = 1.0
SNAPSHOTS_KEPT = 30
WIDE_COVERAGE = (4, 3, 3)  # at the widest of several zooms: every cell of a 4×3 grid, 3 each
WIDE_CORNERS = (0.15, 3)  # and each corner (15 % of width and height from the edges), 3 each
STALL_HINTS = {  # why snapshots gave no passpoint → what to check
    "no marker": "the wand is not in the camera's view (or the IR cut filter is on)",
    "too many": "more bright spots than the wand (reflections, markers)",
    "not moved": "the wand does not move",
    "seen there": "the wand stays where passpoints were taken: carry it to the rest of the "
                  "picture (edges and corners)",
    "marker not in mocap": "the motion capture does not see the wand (is the tracker "
                           "streaming? is the marker label right?)",
}


class Session:
    def __init__(self, node: Node, settings: CalibSettings, store: PoseStore, camera: str,
                 count: int, timeout_s: float,
                 on_pose: Callable[[m.CameraPose, dict], None], review: bool = False,
                 zooms: list[int] | None = None) -> None:
        self.node, self.settings, self.store, self.camera = node, settings, store, camera
        self.timeout_s, self.on_pose, self.review = timeout_s, on_pose, review
        self._decided = threading.Event()
        self._accepted = False
        self.zooms = list(zooms or [])
        track_t: list[float] = []  # one mocap track for every zoom's collector
        track_xyz: list[np.ndarray] = []
        widest = min(self.zooms) if self.zooms else None
        each: list[int | None] = list(self.zooms) if self.zooms else [None]  # None: as it is
        self.collectors = [Collector(count, settings.marker_label, settings.min_spacing_mm,
                                     settings.min_spacing_px, track_t=track_t,
                                     track_xyz=track_xyz)
                           for zoom in each]
        if widest is not None:  # the lens's distortion is measured at the widest step
            wide = self.collectors[self.zooms.index(widest)]
            wide.coverage, wide.corners = WIDE_COVERAGE, WIDE_CORNERS
        self.collector = self.collectors[0]
        self._zoom_index = 0
        self._zoom_since: float | None = None  # the camera's first state at the present zoom
        self.lock = threading.Lock()
        self.running = True
        self.state: m.CollectState = "collecting"
        self.message = ""
        self.mean_error_px: float | None = None
        self._cancel = threading.Event()
        self._pending: deque[m.MarkerDetections] = deque(maxlen=200)
        self._snapshots: OrderedDict[float, bytes] = OrderedDict()
        self._camera_state: m.PtzState | None = None
        self._holding = True  # the camera is held for the collection: its states count
        self._started = time.time()

    # --- fed by bus handlers -----------------------------------------------------------------

    def on_frame(self, msg: m.MarkerFrame) -> None:
        with self.lock:
            self.collector.on_frame(msg)

    def on_detections(self, msg: m.MarkerDetections) -> None:
        if msg.measured_s >= self._started:
            with self.lock:
                self._pending.append(msg)

    def on_snapshot(self, msg: m.CameraFrame) -> None:
        with self.lock:
            self._snapshots[msg.measured_s] = msg.data
            while len(self._snapshots) > SNAPSHOTS_KEPT:
                self._snapshots.popitem(last=False)

    def on_state(self, msg: m.PtzState) -> None:
        if self._holding and msg.status == "calibrating" and msg.measured_s >= self._started:
            if self.zoom is not None and msg.zoom != self.zoom:
                return  # still zooming to the step (or not there yet)
            if self._zoom_since is None:
                self._zoom_since = msg.measured_s
            self._camera_state = msg

    @property
    def zoom(self) -> int | None:
        """The zoom step being collected at (None: one zoom, the hold's)."""
        return self.zooms[self._zoom_index] if self.zooms else None

    @property
    def camera_state(self) -> m.PtzState | None:
        """The camera as it reported itself while held for the collection (its pan and tilt
        are the passpoints')."""
        return self._camera_state

    def stop_holding(self) -> None:
        """The collection is over: a state that comes after the camera is released (it may
        still say "calibrating" while it turns back home) is not the passpoints' pan and
        tilt."""
        self._holding = False

    def cancel(self) -> None:
        self._cancel.set()
        self.decide(accept=False)

    def decide(self, *, accept: bool) -> bool:
        """An operator's word on a pose held for review; False when none is held."""
        if self.state != "review":
            return False
        self._accepted = accept
        self._decided.set()
        return True

    # --- the run -----------------------------------------------------------------------------

    def run(self) -> None:
        try:
            finished = self._collect()
        finally:
            self.stop_holding()
            self._calibration_mode(active=False)
        try:
            if finished:
                self._solve()
        except Exception as err:  # noqa: BLE001 - a failed solve must not kill the service
            log.exception("%s: solving failed", self.camera)
            self._finish("failed", f"solving failed: {err}")
        self.running = False

    def _collect(self) -> bool:
        deadline = self._started + self.timeout_s
        renew_at = progress_at = 0.0
        gained = (0, self._started, Counter(self.collector.skipped))  # passpoints, when, skips
        held = False
        while not self.node.stop.is_set():
            now = time.time()
            if not held and self._camera_state is not None:
                # the stall clock starts again when the PTZ service holds the camera: a
                # collection may start before that service is up, or while the camera turns
                held, gained = True, (gained[0], now, gained[2])
            if self._cancel.is_set():
                self._finish("cancelled", "cancelled")
                return False
            if now > deadline:
                self._finish("failed", f"timed out after {self.timeout_s:g} s with "
                             f"{len(self.collector.times)} of {self.collector.target} "
                             f"passpoints{self._zoom_text()} ({self._skipped_text()})")
                return False
            if len(self.collector.times) != gained[0]:
                gained = (len(self.collector.times), now, Counter(self.collector.skipped))
            elif now - gained[1] > (stall := self.settings.stall_s if held else
                                    max(self.settings.stall_s, self.settings.hold_wait_s)):
                self._finish("failed", self._stalled_text(gained[2], stall))
                return False
            if now >= renew_at:
                self._calibration_mode(active=True)
                renew_at = now + self.settings.lease_s / 3
            self._take_pending(now)
            if self.collector.done:
                if self._zoom_index + 1 >= len(self.collectors):
                    return True
                self._next_zoom()
                renew_at, gained = 0.0, (0, now, Counter(self.collector.skipped))
                held = False
            if now >= progress_at:
                self.publish_progress()
                progress_at = now + PROGRESS_S
            time.sleep(TICK_S)
        return False

    def _next_zoom(self) -> None:
        """The present zoom has its passpoints: on to the next step (the camera is held there
        by the next renewal; its passpoints count once it reports that zoom)."""
        with self.lock:
            self._zoom_index += 1
            self.collector = self.collectors[self._zoom_index]
            self._camera_state, self._zoom_since = None, None
            self._pending.clear()
        log.info("%s: passpoints at zoom %d (%d of %d)", self.camera, self.zoom,
                 self._zoom_index + 1, len(self.zooms))

    def _take_pending(self, now: float) -> None:
        with self.lock:
            while self._pending:
                msg = self._pending[0]
                if self.zooms and (self._zoom_since is None
                                   or msg.measured_s < self._zoom_since):
                    self._pending.popleft()  # taken before the camera stood at this zoom
                    continue
                if not self.collector.track_covers(msg.measured_s) and \
                        now - msg.measured_s < MOCAP_WAIT_S:
                    break
                self._pending.popleft()
                if self.collector.done:
                    continue
                if self.collector.on_detections(msg) is None:
                    self._keep_image(msg, sum(len(c.times) for c in self.collectors) - 1)

    def _keep_image(self, msg: m.MarkerDetections, index: int) -> None:
        jpeg = self._snapshots.get(msg.measured_s)
        if jpeg is None:
            return
        try:
            image = decode_gray(jpeg)
        except JpegError:  # an image that does not decode is just not kept
            return
        u, v = self.collector.pixels[-1]  # the passpoint just taken; ``index`` over all zooms
        markers = tuple(marker_of(d) for d in msg.markers)
        chosen = tuple(mk for mk in markers if mk.u == u and mk.v == v)
        drawn = annotate(image, Detection(msg.status, msg.threshold, chosen, markers))
        cv2.imwrite(str(self.store.image_dir(self.camera) / f"{index:03d}.jpg"), drawn)

    def _solve(self) -> None:
        state = self.camera_state
        if state is None:
            self._finish("failed", "the camera never reported being in calibration mode")
            return
        self.state = "solving"
        self.publish_progress()
        if self.zooms:
            self._solve_zooms(state)
            return
        with self.lock:
            points, track = self.collector.passpoints(), self.collector.track()
        self.store.save_inputs(self.camera, points, track)
        s = self.settings
        options = Options(focal_mm=state.focal_mm, fit_focal=s.fit_focal, track=track,
                          max_time_offset_s=s.max_time_offset_s, inlier_px=s.inlier_px,
                          max_mean_error_px=s.max_mean_error_px)
        try:
            solution = in_worker(solve_one_zoom, points, options)
        except CalibrationError as err:
            self._finish("failed", str(err))
            return
        mount = mount_pose(solution.pose, state.pan_deg, state.tilt_deg)
        pose = m.CameraPose(
            measured_s=time.time(), camera=self.camera, **mount.fields(),
            focal_mm=solution.focal_mm, mean_error_px=solution.mean_error_px,
            passpoints=len(solution.inliers), time_offset_s=solution.time_offset_s or 0.0)
        report = solution.report() | {"pan_deg": state.pan_deg, "tilt_deg": state.tilt_deg,
                                      "zoom": state.zoom}
        rejected = report["rejected"]
        spread = float(np.max(solution.position_std_mm))
        self._take(pose, report, f"{len(solution.inliers)} passpoints, {len(rejected)} rejected, "
                   f"position ±{spread:.1f} mm (1σ), clock offset "
                   f"{1e3 * (solution.time_offset_s or 0.0):.1f} ms; one zoom: the zoom curve "
                   "is the data sheet's straight line")

    def _solve_zooms(self, state: m.PtzState) -> None:
        """One fit over every zoom's passpoints: the pose and the lens."""
        with self.lock:
            by_zoom = {z: c.passpoints() for z, c in zip(self.zooms, self.collectors,
                                                          strict=True)}
            track = self.collector.track()
        self.store.save_inputs(self.camera, Passpoints.joined(by_zoom), track)
        s = self.settings
        options = Options(track=track, max_time_offset_s=s.max_time_offset_s,
                          inlier_px=s.inlier_px, max_mean_error_px=s.max_mean_error_px)
        try:
            fit, first, not_drawn = in_worker(solve_zooms_and_plot, by_zoom, options,
                                              self.store.camera_dir(self.camera) / "lens.png")
        except CalibrationError as err:
            self._finish("failed", str(err))
            return
        if not_drawn is not None:  # a picture that cannot be drawn is only missed
            log.warning("%s: no lens.png: %s", self.camera, not_drawn)
        mount = mount_pose(fit.pose, state.pan_deg, state.tilt_deg)
        lens = [m.LensAtZoom.model_validate(at) for at in fit.at_zoom()]
        used = sum(len(k) for k in fit.inliers)
        pose = m.CameraPose(
            measured_s=time.time(), camera=self.camera, **mount.fields(),
            focal_mm=fit.focals_mm[0], mean_error_px=fit.mean_error_px(), passpoints=used,
            time_offset_s=first.time_offset_s or 0.0, lens=lens)
        report = fit.report() | {"pan_deg": state.pan_deg, "tilt_deg": state.tilt_deg,
                                 "time_offset_s": round(first.time_offset_s or 0.0, 5)}
        self._take(pose, report, f"{used} passpoints at {len(fit.zooms)} zoom steps, focal "
                   f"{fit.focals_mm[0]:.2f}–{fit.focals_mm[-1]:.2f} mm, clock offset "
                   f"{1e3 * (first.time_offset_s or 0.0):.1f} ms")

    def _take(self, pose: m.CameraPose, report: dict, summary: str) -> None:
        """The solved pose: held for review if asked, then versioned, stored and published
        by the service."""
        self.mean_error_px = pose.mean_error_px
        if self.review and not self._reviewed(summary):
            return
        self.on_pose(pose, report)
        self._finish("done", summary)
        log.info("%s: pose (%.0f, %.0f, %.0f) mm, (%.2f, %.2f, %.2f)°, %.2f px", self.camera,
                 pose.x_mm, pose.y_mm, pose.z_mm, pose.rx_deg, pose.ry_deg, pose.rz_deg,
                 pose.mean_error_px)

    def _reviewed(self, summary: str) -> bool:
        """Hold the solved pose for an operator's accept (True) or discard, at most
        ``review_s``; the old pose stays meanwhile and after a discard."""
        self._finish("review", f"{summary}: accept or discard")
        deadline = time.monotonic() + self.settings.review_s
        while not self._decided.wait(PROGRESS_S):
            if self.node.stop.is_set() or time.monotonic() > deadline:
                self._finish("discarded", f"not accepted within {self.settings.review_s:g} s: "
                             "the camera keeps its pose")
                return False
            self.publish_progress()
        if not self._accepted:
            self._finish("discarded", "discarded: the camera keeps its pose")
        return self._accepted

    # --- the bus side ------------------------------------------------------------------------

    def _calibration_mode(self, active: bool) -> None:
        hold = self.settings.hold.get(self.camera)
        zoom = self.zoom if self.zoom is not None else hold.zoom if hold else None
        self.node.bus.publish(keys.PTZ_CALIBRATION, m.CalibrationMode(
            measured_s=time.time(), camera=self.camera, active=active,
            pan_deg=hold.pan_deg if hold else None, tilt_deg=hold.tilt_deg if hold else None,
            zoom=zoom, lease_s=self.settings.lease_s),
            camera=self.camera)

    def _finish(self, state: m.CollectState, message: str) -> None:
        self.state, self.message = state, message
        (log.info if state == "done" else log.warning)("%s: collection %s: %s", self.camera,
                                                       state, message)
        self.publish_progress()

    def publish_progress(self) -> None:
        c = self.collector
        self.node.bus.publish(keys.CALIB_PROGRESS, m.CollectProgress(
            measured_s=time.time(), camera=self.camera, state=self.state,
            passpoints=sum(len(k.times) for k in self.collectors),
            target=sum(k.target for k in self.collectors), snapshots=c.snapshots,
            skipped=dict(c.skipped), message=m.text(self.message or self._coverage_text()),
            mean_error_px=self.mean_error_px, zoom=self.zoom,
            zooms_done=sum(k.done for k in self.collectors), zooms=len(self.zooms)),
            camera=self.camera)

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
        missing = self.collector.uncovered() if self.state == "collecting" else []
        if not missing:
            return ""
        return f"carry the wand to the picture's {', '.join(missing)}"

    def _zoom_text(self) -> str:
        if not self.zooms:
            return ""
        return f" at zoom {self.zoom} (step {self._zoom_index + 1} of {len(self.zooms)})"

    def _skipped_text(self) -> str:
        skipped = self.collector.skipped
        return ", ".join(f"{n} {why}" for why, n in skipped.most_common()) or "none skipped"
