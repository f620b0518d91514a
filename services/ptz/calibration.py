"""Calibration mode of a PTZ camera (paper §2.1): held still, IR cut filter off, every snapshot
run through the marker detector and published with its capture time.

A collector asks for the mode with ``CalibrationMode`` requests and renews them; the mode ends
when it says so or its lease runs out, so a collector that dies frees the camera.

The camera is held where the request says; what the request leaves open comes from the
camera's home position (VAPIX ``move=home``: the home preset a lab sets to look into the
crater), never from wherever someone left it. Once it stands there, that is the hold. Moved
away (another client, someone at the camera's page), it is sent back to the hold at most
once a second. Detections are published only while the camera stands still at the hold (its
position unchanged since the previous snapshot), so that no passpoint comes from a moving
camera or a foreign view.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass

from common import messages as m
from common.camera import PtzLimits
from common.markers import detect, to_message
from services.ptz.camera import PtzCamera, decode_jpeg

log = logging.getLogger(__name__)
STILL_DEG = 0.01
AT_TARGET_DEG = 0.05
HOME_SETTLE_S = 1.0  # after move=home: longer than a command's latency before it moves
REHOLD_S = 1.0  # a camera moved away from the hold is sent back at most this often


def _wrap(angle_deg: float) -> float:
    return (angle_deg + 180.0) % 360.0 - 180.0


def _asked(msg: m.CalibrationMode) -> tuple[float | None, float | None, int | None]:
    return msg.pan_deg, msg.tilt_deg, msg.zoom


def _within(msg: m.CalibrationMode, limits: PtzLimits) -> m.CalibrationMode:
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


Hold = tuple[float, float, int]


@dataclass
class CalibrationHold:
    camera: PtzCamera
    publish_detections: Callable[[m.MarkerDetections], object]
    publish_snapshot: Callable[[m.CameraFrame], object]
    max_markers: int = 8
    moved: Callable[[float | None, float | None], None] = lambda _pan, _tilt: None  # each
    # move it sends (None: to home, or left as it is), for the manual-override detector
    monotonic: Callable[[], float] = time.monotonic  # the clock of its waits
    wall: Callable[[], float] = time.time  # the clock of its snapshots' capture times
    request: m.CalibrationMode | None = None
    expires_at: float = 0.0
    hold: Hold | None = None  # where the camera is held; None until it stood at home
    rehold_count: int = 0  # times the camera was found moved away and sent back
    _last_position: tuple[float, float, int] | None = None
    _seq: int = 0
    _infrared_asserted: float = 0.0  # monotonic time the IR-cut filter was last set off
    _homed_at: float = 0.0  # monotonic time of the last move=home
    _rehold_at: float = 0.0  # monotonic time from which a re-hold may be sent
    _commanded: bool = False  # the request's hold was sent to the camera (not lost to an error)

    def active(self, now: float) -> bool:
        return self.request is not None and now < self.expires_at

    def on_request(self, msg: m.CalibrationMode, now: float, limits: PtzLimits
                   ) -> None:
        """Enter, renew or leave the mode; where it holds the camera is clamped to the
        camera's ``limits``. Camera errors propagate (PtzError)."""
        if not msg.active:
            if self.request is not None:
                self.leave()
            return
        msg = _within(msg, limits)
        entering = not self.active(now)
        moved = self.request is None or _asked(msg) != _asked(self.request)
        self.request, self.expires_at = msg, now + msg.lease_s
        if entering or moved:
            self._commanded = False
        if entering:
            log.info("%s: calibration mode (pan %s, tilt %s, zoom %s)", self.camera.name,
                     msg.pan_deg, msg.tilt_deg, msg.zoom)
            self._last_position = None
            self._infrared()
        if not self._commanded:
            self._go_to_hold(msg)

    def _go_to_hold(self, msg: m.CalibrationMode) -> None:
        """Command the hold: the request's pan, tilt and zoom; home for what it leaves open.
        A command the camera did not take (PtzError) is sent again by the next renewal or
        snapshot: the camera is never held wherever it happened to stand."""
        pan, tilt, zoom = _asked(msg)
        if pan is not None and tilt is not None and zoom is not None:
            self.hold = (pan, tilt, zoom)
        else:
            self.hold, self._homed_at = None, self.monotonic()
            self.moved(None, None)
            self.camera.home()
        if any(v is not None for v in _asked(msg)):
            self.moved(msg.pan_deg, msg.tilt_deg)
            self.camera.move_to(msg.pan_deg, msg.tilt_deg, msg.zoom)
        self._commanded = True

    def _at_hold(self, pan: float, tilt: float, zoom: int) -> bool:
        """True once the camera stands at the hold (a move takes effect only after the
        camera's command latency: standing still is not enough)."""
        if self.hold is None:
            return False
        hold_pan, hold_tilt, hold_zoom = self.hold
        return (abs(_wrap(pan - hold_pan)) < AT_TARGET_DEG
                and abs(tilt - hold_tilt) < AT_TARGET_DEG and zoom == hold_zoom)

    def _keep_hold(self, position: Hold, still: bool) -> bool:
        """Learn the hold once the camera stands at home; send it back when it stands
        elsewhere. True when it stands at the hold now."""
        if not still:
            return False
        if self.hold is None:
            if self.monotonic() - self._homed_at >= HOME_SETTLE_S:
                self.hold = position
                log.info("%s: held at pan %.2f°, tilt %.2f°, zoom %d", self.camera.name,
                         *position)
            return self.hold is not None
        if self._at_hold(*position):
            return True
        if self.monotonic() >= self._rehold_at:
            self.rehold_count += 1
            log.warning("%s: moved away from its calibration hold (now pan %.1f°, tilt "
                        "%.1f°): sent back to pan %.1f°, tilt %.1f°", self.camera.name,
                        position[0], position[1], self.hold[0], self.hold[1])
            self.moved(self.hold[0], self.hold[1])
            self.camera.move_to(*self.hold)
            self._rehold_at = self.monotonic() + REHOLD_S
        return False

    def _infrared(self) -> None:
        self.camera.set_ir_cut_filter("off")
        self._infrared_asserted = self.monotonic()

    def leave(self) -> None:
        log.info("%s: calibration mode ends", self.camera.name)
        self.request = None
        self.camera.set_ir_cut_filter("auto")

    def cycle(self) -> None:
        """One snapshot: detect, publish the image and — if the camera stood still — the
        detections. Camera errors propagate (PtzError)."""
        if self.monotonic() - self._infrared_asserted > REASSERT_INFRARED_S:
            self._infrared()
        if not self._commanded and self.request is not None:
            self._go_to_hold(self.request)
        captured = self.wall()
        jpeg = self.camera.snapshot_jpeg()
        answered_after = self.wall() - captured
        position = self.camera.position()
        now_position = (position.pan_deg, position.tilt_deg, position.zoom)
        still = self._last_position is not None and (
            abs(now_position[0] - self._last_position[0]) < STILL_DEG
            and abs(now_position[1] - self._last_position[1]) < STILL_DEG
            and now_position[2] == self._last_position[2])
        self._last_position = now_position
        still = self._keep_hold(now_position, still)
        image = decode_jpeg(jpeg, self.camera.name)
        height, width = image.shape
        self._seq += 1
        self.publish_snapshot(m.CameraFrame(measured_s=captured, camera=self.camera.name,
                                            seq=self._seq, width_px=width, height_px=height,
                                            encoding="jpeg", data=jpeg))
        if still:
            result = detect(image, max_markers=self.max_markers)
            self.publish_detections(to_message(result, self.camera.name, captured, width,
                                               height, answered_after))
