"""One passpoint collection for one camera, wired: calibration mode on, passpoints in, pose out.

The rules (zoom steps, stalls, time-outs, which detections count) are ``collection.py``'s, on
the clock this session gives it; here they meet the bus (the handlers feed it mocap frames,
detections, snapshots and camera states; its actions publish and keep images), the solving
worker and an operator's review. Runs in its own thread.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import OrderedDict
from collections.abc import Callable

import cv2
import numpy as np

from common import keys
from common import messages as m
from common.camera import mount_pose
from common.jpeg import JpegError, decode_gray
from common.markers import Detection, annotate, marker_of
from common.node import Node
from common.passpoints import CalibrationError, Passpoints
from services.calib.collection import (
    PROGRESS_S,
    Action,
    Collected,
    Collection,
    Ended,
    HoldCamera,
    KeepImage,
    PublishProgress,
)
from services.calib.options import Options
from services.calib.settings import CalibSettings
from services.calib.store import PoseStore
from services.calib.worker import in_worker, solve_one_zoom, solve_zooms_and_plot

log = logging.getLogger(__name__)
TICK_S = 0.05
SNAPSHOTS_KEPT = 30


class Session:
    def __init__(self, node: Node, settings: CalibSettings, store: PoseStore, camera: str,
                 count: int, timeout_s: float,
                 on_pose: Callable[[m.CameraPose, dict], None], review: bool = False,
                 zooms: list[int] | None = None, step_count: int | None = None) -> None:
        self.node, self.settings, self.store, self.camera = node, settings, store, camera
        self.on_pose, self.review = on_pose, review
        self.collection = Collection(settings, camera, count, timeout_s, zooms,
                                     started_s=time.time(),
                                     step_count=step_count or settings.step_count)
        self._decided = threading.Event()
        self._accepted = False
        self.lock = threading.Lock()
        self.running = True
        self.state: m.CollectState = "collecting"
        self.message = ""
        self.mean_error_px: float | None = None
        self._snapshots: OrderedDict[float, bytes] = OrderedDict()

    # --- fed by bus handlers -----------------------------------------------------------------

    def on_frame(self, msg: m.MarkerFrame) -> None:
        with self.lock:
            self.collection.on_frame(msg)

    def on_detections(self, msg: m.MarkerDetections) -> None:
        with self.lock:
            self.collection.on_detections(msg)

    def on_snapshot(self, msg: m.CameraFrame) -> None:
        with self.lock:
            self._snapshots[msg.measured_s] = msg.data
            while len(self._snapshots) > SNAPSHOTS_KEPT:
                self._snapshots.popitem(last=False)

    def on_state(self, msg: m.PtzState) -> None:
        with self.lock:
            self.collection.on_state(msg)

    def cancel(self) -> None:
        with self.lock:
            self.collection.cancel()
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
            with self.lock:
                self.collection.stop_holding()
            self._calibration_mode(active=False, zoom=self.collection.zoom)
        try:
            if finished:
                self._solve()
        except Exception as err:  # noqa: BLE001 - a failed solve must not kill the service
            log.exception("%s: solving failed", self.camera)
            self._finish("failed", f"solving failed: {err}")
        self.running = False

    def _collect(self) -> bool:
        """The collection's rules stepped on the wall clock until it is collected (True) or
        ended, or the service stops."""
        while True:
            with self.lock:
                actions = self.collection.step(time.time())
            for action in actions:
                if isinstance(action, Collected):
                    return True
                if isinstance(action, Ended):
                    self._finish(action.state, action.message)
                    return False
                self._carry_out(action)
            if self.node.stop.wait(TICK_S):
                return False

    def _carry_out(self, action: Action) -> None:
        if isinstance(action, HoldCamera):
            self._calibration_mode(active=True, zoom=action.zoom)
        elif isinstance(action, PublishProgress):
            self.publish_progress()
        elif isinstance(action, KeepImage):
            self._keep_image(action)

    def _keep_image(self, kept: KeepImage) -> None:
        jpeg = self._snapshots.get(kept.detections.measured_s)
        if jpeg is None:
            return
        try:
            image = decode_gray(jpeg)
        except JpegError:  # an image that does not decode is just not kept
            return
        markers = tuple(marker_of(d) for d in kept.detections.markers)
        chosen = tuple(mk for mk in markers if (mk.u, mk.v) == kept.pixel)
        drawn = annotate(image, Detection(kept.detections.status, kept.detections.threshold,
                                          chosen, markers))
        cv2.imwrite(str(self.store.image_dir(self.camera) / f"{kept.index:03d}.jpg"), drawn)

    def _solve(self) -> None:
        c = self.collection
        state = c.camera_state
        if state is None:
            self._finish("failed", "the camera never reported being in calibration mode")
            return
        self.state = "solving"
        self.publish_progress()
        if c.zooms:
            self._solve_zooms(state)
            return
        with self.lock:
            points, track = c.collector.passpoints(), c.collector.track()
        self.store.save_inputs(self.camera, points, track)
        s = self.settings
        options = Options.in_picture(
            c.picture_px, inlier_px=s.inlier_px, max_mean_error_px=s.max_mean_error_px,
            focal_px=state.focal_px, fit_focal=s.fit_focal, track=track,
            max_time_offset_s=s.max_time_offset_s)
        try:
            solution = in_worker(solve_one_zoom, points, options)
        except CalibrationError as err:
            self._finish("failed", str(err))
            return
        mount = mount_pose(solution.pose, state.pan_deg, state.tilt_deg)
        pose = m.CameraPose(
            measured_s=time.time(), camera=self.camera, **mount.fields(),
            focal_px=solution.focal_px, width_px=options.picture_px[0],
            height_px=options.picture_px[1], mean_error_px=solution.mean_error_px,
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
            c = self.collection
            by_zoom = {z: k.passpoints() for z, k in zip(c.zooms, c.collectors, strict=True)}
            track = c.collector.track()
        self.store.save_inputs(self.camera, Passpoints.joined(by_zoom), track)
        s = self.settings
        options = Options.in_picture(
            c.picture_px, inlier_px=s.inlier_px, max_mean_error_px=s.max_mean_error_px,
            track=track, max_time_offset_s=s.max_time_offset_s)
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
            focal_px=fit.focals_px[0], width_px=fit.picture_px[0], height_px=fit.picture_px[1],
            principal_u_px=None if fit.principal_px is None else fit.principal_px[0],
            principal_v_px=None if fit.principal_px is None else fit.principal_px[1],
            mean_error_px=fit.mean_error_px(), passpoints=used,
            time_offset_s=first.time_offset_s or 0.0, lens=lens)
        report = fit.report() | {"pan_deg": state.pan_deg, "tilt_deg": state.tilt_deg,
                                 "time_offset_s": round(first.time_offset_s or 0.0, 5)}
        self._take(pose, report, f"{used} passpoints at {len(fit.zooms)} zoom steps, focal "
                   f"{fit.focals_px[0]:.0f}–{fit.focals_px[-1]:.0f} px, clock offset "
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

    def _calibration_mode(self, *, active: bool, zoom: int | None) -> None:
        """Calibration mode on (held at ``zoom``, or at the hold's own when None) or off."""
        hold = self.settings.hold.get(self.camera)
        zoom = zoom if zoom is not None else hold.zoom if hold else None
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
        with self.lock:
            progress = self.collection.progress(time.time(), self.state, self.message,
                                                self.mean_error_px)
        self.node.bus.publish(keys.CALIB_PROGRESS, progress, camera=self.camera)
