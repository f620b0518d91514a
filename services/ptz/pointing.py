"""Does the camera see the robot where its pose says? (pure) The pointing check.

Every preview carries the markers the detector found and the pixel where the robot marker
should be (the calibrated pose at the camera's reported pan and tilt). Their disagreement is
measured as an angle: between the rays of that pixel and of the nearest marker found. The aim
error in ``stb/ptz/{camera}/state`` is computed from the same pose and so cannot see a wrong
pose; this check can: a poisoned or stale pose points the camera elsewhere, and the robot's
marker is then far from where the pose puts it, or not in the picture at all.

The robot's retro-reflective marker is bright only when the camera sees infrared (IR-cut
filter off): so a preview without any marker counts only if it was taken in infrared (the
preview loop takes one when ``InfraredSchedule`` says a check is due), and while infrared
previews are taken,
only they are judged: in daylight the bright spots found are reflections and other lights
(with previews at 2 Hz and an infrared one every 2 s, three daylight previews in a row that
showed a reflection far from the robot made a problem of a camera that pointed right).
Without infrared previews, daylight previews that show markers are judged. A single preview
proves little (a
reflection, the robot behind the crater's rim): only ``persist`` disagreeing previews in a
row make a problem, and one agreeing preview ends it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from common import messages as m
from common.camera import Intrinsics, undistort_pixels

NOT_SEEN = math.inf  # no marker in the picture where the robot should be


def pointing_error_deg(preview: m.PtzPreview, intr: Intrinsics, min_radius_px: float = 0.0
                       ) -> float | None:
    """The angle from where the robot marker should appear to the nearest marker found
    (``NOT_SEEN`` if none was found); None when there is nothing to judge: no pose or robot,
    the robot outside the picture, or its marker smaller there than ``min_radius_px`` (too
    small for the detector to find: its absence says nothing about the pose)."""
    if preview.robot_px is None:
        return None
    if preview.robot_radius_px is not None and preview.robot_radius_px < min_radius_px:
        return None
    u, v = preview.robot_px
    if not (0 <= u < preview.width_px and 0 <= v < preview.height_px):
        return None
    if not preview.markers:
        return NOT_SEEN
    nearest = min(preview.markers, key=lambda d: math.hypot(d.u_px - u, d.v_px - v))
    a, b = _ray(u, v, intr), _ray(nearest.u_px, nearest.v_px, intr)
    return math.degrees(math.acos(min(1.0, float(a @ b))))


def _ray(u: float, v: float, intr: Intrinsics) -> np.ndarray:
    """The unit ray of pixel (u, v) in the camera frame (x = optical axis, eq. 3 inverted,
    the lens's distortion undone)."""
    u, v = undistort_pixels(np.array([[u, v]]), intr)[0]
    ray = np.array([1.0, (u - intr.cy_px) / intr.fy_px, (v - intr.cz_px) / intr.fz_px])
    return ray / np.linalg.norm(ray)


class PointingCheck:
    """The latest measured pointing error, and whether the last ``persist`` judged previews
    all disagreed by more than ``tolerance_deg``."""

    def __init__(self, tolerance_deg: float, persist: int, daylight: bool = True,
                 min_radius_px: float = 0.0) -> None:
        """``daylight``: judge previews taken with the IR-cut filter on too (False while the
        preview loop takes infrared ones); ``min_radius_px``: previews in which the robot
        marker would be smaller are not judged."""
        self.tolerance_deg, self.persist, self.daylight = tolerance_deg, persist, daylight
        self.min_radius_px = min_radius_px
        self.error_deg: float | None = None  # of the latest judged preview
        self._misses = 0

    def observe(self, preview: m.PtzPreview, intr: Intrinsics, infrared: bool) -> bool:
        """Judge ``preview``; False when there was nothing to judge in it."""
        if not infrared and not self.daylight:
            return False
        error = pointing_error_deg(preview, intr, self.min_radius_px)
        if error is None or (error == NOT_SEEN and not infrared):
            return False
        self.error_deg = error
        self._misses = self._misses + 1 if error > self.tolerance_deg else 0
        return True

    def forget(self) -> None:
        """A new pose: what was measured with the old one no longer counts."""
        self.error_deg, self._misses = None, 0

    def doubting(self) -> bool:
        """The latest judged preview disagreed (a problem, or on the way to one)."""
        return self._misses > 0

    def problem(self) -> str | None:
        """Why the camera's pointing is not to be trusted, or None."""
        if self._misses < self.persist:
            return None
        if self.error_deg == NOT_SEEN:
            return (f"pointing: the robot marker not seen where the pose puts it in "
                    f"{self._misses} previews in a row (wrong pose? occluded?)")
        # the spot may be another marker (a static one, with the robot hidden): not named the
        # robot's
        return (f"pointing: the nearest marker seen {self.error_deg:.1f}° from where the pose "
                f"puts the robot's in {self._misses} previews in a row (wrong pose? the robot "
                f"hidden?)")


@dataclass
class InfraredSchedule:
    """When the next preview is taken in infrared for the check. The IR-cut filter is a
    mechanical switch: each switch wears it and flickers the camera's video, so it is switched
    only when a check is due — at the first preview with a pose, and again for each new pose
    or after the camera was lost (``again``); then every ``every_s`` (minutes); every
    ``confirm_s`` while the latest judged preview disagreed, so that a wrong pose is reported
    (and its end seen) within seconds; never while a recording runs unless
    ``while_recording``. An infrared preview that judged nothing (the robot out of the
    picture, its marker too small there) is tried again after ``confirm_s``, then twice as
    long each time, up to ``every_s``. ``every_s`` 0: never."""

    every_s: float
    confirm_s: float
    while_recording: bool = False
    last_s: float | None = None  # when the latest infrared preview was taken
    _judged: bool = False  # and it judged the pose
    _retry_s: float = 0.0  # the wait after one that did not

    def due(self, now: float, *, doubting: bool, recording: bool) -> bool:
        if self.every_s <= 0 or (recording and not self.while_recording):
            return False
        if self.last_s is None:
            return True
        if doubting:
            wait = self.confirm_s
        elif not self._judged:
            wait = self._retry_s
        else:
            wait = self.every_s
        return now - self.last_s >= min(wait, self.every_s)

    def taken(self, now: float) -> None:
        self._retry_s = self.confirm_s if self._judged or self.last_s is None else \
            2 * self._retry_s
        self.last_s, self._judged = now, False

    def judged(self) -> None:
        """The infrared preview just taken judged the pose."""
        self._judged = True

    def again(self) -> None:
        """Check at the next preview (a new pose, the camera back)."""
        self.last_s, self._judged = None, False
