"""Calibration mode of a PTZ camera (paper §2.1): held still, IR cut filter off, every snapshot
run through the marker detector and published with its capture time.

A collector asks for the mode with ``CalibrationMode`` requests and renews them; the mode ends
when it says so or its lease runs out, so a collector that dies frees the camera. Detections
are published only while the camera stands still (its position unchanged since the previous
snapshot, and where the request holds it), so that no passpoint comes from a moving camera.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass

from common import messages as m
from common.markers import detect, to_message
from services.ptz.aim import Limits
from services.ptz.camera import PtzCamera, decode_jpeg

log = logging.getLogger(__name__)
STILL_DEG = 0.01
AT_TARGET_DEG = 0.05


def _wrap(angle_deg: float) -> float:
    return (angle_deg + 180.0) % 360.0 - 180.0


def _within(msg: m.CalibrationMode, limits: Limits) -> m.CalibrationMode:
    """The request with its pan, tilt and zoom inside the camera's limits."""
    pan, tilt, zoom = limits.clamp(msg.pan_deg if msg.pan_deg is not None else 0.0,
                                   msg.tilt_deg if msg.tilt_deg is not None else 0.0,
                                   msg.zoom if msg.zoom is not None else limits.min_zoom)
    return msg.model_copy(update={
        "pan_deg": None if msg.pan_deg is None else pan,
        "tilt_deg": None if msg.tilt_deg is None else tilt,
        "zoom": None if msg.zoom is None else int(zoom)})


# The preview thread's infrared snapshot (the pointing check) sets the filter back to auto: if
# that crossed the entry into this mode, the filter is set off again within this many seconds.
REASSERT_INFRARED_S = 1.0


@dataclass
class CalibrationMode:
    camera: PtzCamera
    publish_detections: Callable[[m.MarkerDetections], None]
    publish_snapshot: Callable[[m.CameraFrame], None]
    max_markers: int = 8
    request: m.CalibrationMode | None = None
    expires_at: float = 0.0
    _last_position: tuple[float, float, int] | None = None
    _seq: int = 0
    _infrared_asserted: float = 0.0  # monotonic time the IR-cut filter was last set off

    def active(self, now: float) -> bool:
        return self.request is not None and now < self.expires_at

    def on_request(self, msg: m.CalibrationMode, now: float, limits: Limits
                   ) -> None:
        """Enter, renew or leave the mode; where it holds the camera is clamped to the
        camera's ``limits``. Camera errors propagate (PtzError)."""
        if not msg.active:
            if self.request is not None:
                self.leave()
            return
        msg = _within(msg, limits)
        entering = not self.active(now)
        self.request, self.expires_at = msg, now + msg.lease_s
        if entering:
            log.info("%s: calibration mode (pan %s, tilt %s, zoom %s)", self.camera.name,
                     msg.pan_deg, msg.tilt_deg, msg.zoom)
            self._last_position = None
            self._infrared()
            if msg.pan_deg is not None or msg.tilt_deg is not None or msg.zoom is not None:
                self.camera.move_to(msg.pan_deg, msg.tilt_deg, msg.zoom)

    def _at_requested(self, pan: float, tilt: float, zoom: int) -> bool:
        """True once the camera stands where the request holds it (a move takes effect only
        after the camera's command latency: standing still is not enough)."""
        r = self.request
        if r is None:
            return False
        return ((r.pan_deg is None or abs(_wrap(pan - r.pan_deg)) < AT_TARGET_DEG)
                and (r.tilt_deg is None or abs(tilt - r.tilt_deg) < AT_TARGET_DEG)
                and (r.zoom is None or zoom == r.zoom))

    def _infrared(self) -> None:
        self.camera.set_ir_cut_filter("off")
        self._infrared_asserted = time.monotonic()

    def leave(self) -> None:
        log.info("%s: calibration mode ends", self.camera.name)
        self.request = None
        self.camera.set_ir_cut_filter("auto")

    def cycle(self) -> None:
        """One snapshot: detect, publish the image and — if the camera stood still — the
        detections. Camera errors propagate (PtzError)."""
        if time.monotonic() - self._infrared_asserted > REASSERT_INFRARED_S:
            self._infrared()
        captured = time.time()
        jpeg = self.camera.snapshot_jpeg()
        position = self.camera.position()
        now_position = (position.pan_deg, position.tilt_deg, position.zoom)
        still = self._last_position is not None and (
            abs(now_position[0] - self._last_position[0]) < STILL_DEG
            and abs(now_position[1] - self._last_position[1]) < STILL_DEG
            and now_position[2] == self._last_position[2])
        self._last_position = now_position
        still = still and self._at_requested(*now_position)
        image = decode_jpeg(jpeg, self.camera.name)
        height, width = image.shape
        self._seq += 1
        self.publish_snapshot(m.CameraFrame(measured_s=captured, camera=self.camera.name,
                                            seq=self._seq, width_px=width, height_px=height,
                                            encoding="jpeg", data=jpeg))
        if still:
            result = detect(image, max_markers=self.max_markers)
            self.publish_detections(to_message(result, self.camera.name, captured, width,
                                               height))
