"""When and where to move the camera to follow the robot (pure; times in seconds).

At a long zoom the picture is a few degrees wide: the dead band shrinks with the field of
view (a fixed 0.3° is 7 % of a 4.5° picture), and when the robot strays from the picture's
central part (``central``: a fraction of the half-height; the camera is late, the robot turned)
the camera zooms out until the robot is well inside again, and back in once it is re-centred
(within half that part at the wanted zoom). The prediction that makes up for the camera's
latency does not change with the zoom: the latency does not.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from common.camera import Pose, PtzLimits
from common.ptz_lens import PtzLens
from common.volume import Volume
from services.ptz.aim import aim_at, aim_error_deg, predict, zoom_for_size


@dataclass(frozen=True)
class Command:
    pan_deg: float
    tilt_deg: float
    zoom: int
    measured_s: float  # the robot sample it is based on


@dataclass
class Follower:
    """Turns robot positions into rate-limited, dead-banded camera commands.

    The target is the robot predicted ``latency_s`` past *now* from its measured position and
    velocity (bounded), to make up for the camera's command latency and motion.
    """

    limits: PtzLimits = PtzLimits()
    deadband_deg: float = 0.3
    latency_s: float = 0.25
    min_interval_s: float = 0.1
    zoom: int = 1
    target_size_mm: float | None = None
    image_fraction: float = 0.3
    volume: Volume = Volume()
    max_age_s: float = 1.0
    lens: PtzLens = PtzLens()  # the calibrated camera's, or the data sheet's straight line
    central: float = 0.6
    _last: Command | None = None
    _last_at: float = -math.inf
    _seen: tuple[float, float, int] | None = None  # the camera's reported pan, tilt, zoom
    _backed_out: int | None = None  # the wider zoom taken while the robot is off-centre

    def seen(self, pan_deg: float, tilt_deg: float, zoom: int) -> None:
        """Where the camera was reported to look (its position query)."""
        self._seen = (pan_deg, tilt_deg, zoom)

    def half_view_deg(self, zoom: float) -> float:
        """Half the picture's height as an angle at ``zoom`` (the narrower field of view)."""
        return self.lens.half_view_deg(zoom)

    def forget(self) -> None:
        """Send the next command whatever the last one was (the camera was moved away)."""
        self._last, self._last_at = None, -math.inf

    def command(self, now_s: float, position_mm: np.ndarray, velocity_mm_s: np.ndarray,
                measured_s: float, pose: Pose) -> Command | None:
        """A command to send now, or None (too soon, too small, or a sample to ignore)."""
        if now_s - self._last_at < self.min_interval_s:
            return None
        if not self.volume.contains(position_mm) or now_s - measured_s > self.max_age_s:
            return None
        ahead = (now_s - measured_s) + self.latency_s
        target = predict(position_mm, velocity_mm_s, ahead, max_ahead_s=1.0)
        current = (self._last.pan_deg, self._last.tilt_deg) if self._last else (0.0, 0.0)
        pan, tilt = aim_at(target, pose, self.limits, current_pan_deg=current[0],
                           current_tilt_deg=current[1])
        zoom = self._kept_in_view(self._zoom(target, pose), target, pose)
        deadband = self.deadband_deg * min(1.0, self.half_view_deg(zoom)
                                           / self.half_view_deg(self.limits.min_zoom))
        if self._last is not None and zoom == self._last.zoom and max(
                abs(pan - self._last.pan_deg), abs(tilt - self._last.tilt_deg)) < deadband:
            return None
        self._last = Command(pan, tilt, zoom, measured_s)
        self._last_at = now_s
        return self._last

    def _zoom(self, target: np.ndarray, pose: Pose) -> int:
        if self.target_size_mm is None:
            return self.zoom
        distance = float(np.linalg.norm(target - pose.position))
        return zoom_for_size(distance, object_mm=self.target_size_mm,
                             image_fraction=self.image_fraction, limits=self.limits,
                             lens=self.lens)

    def _kept_in_view(self, wanted: int, target: np.ndarray, pose: Pose) -> int:
        """``wanted``, or a wider zoom while the robot is off the picture's centre."""
        if self._seen is None:
            return wanted
        pan, tilt, zoom = self._seen
        off = aim_error_deg(target, pose, pan, tilt)
        if off > self.central * self.half_view_deg(zoom):
            view = self.lens.zoom_for_view(min(1.5 * off / self.central, 80.0))
            wider = max(min(view, wanted), self.limits.min_zoom)
            self._backed_out = wider if self._backed_out is None else min(wider,
                                                                          self._backed_out)
            return self._backed_out
        if self._backed_out is not None and \
                off > self.central / 2 * self.half_view_deg(wanted):
            return self._backed_out  # not re-centred yet: stay wide
        self._backed_out = None
        return wanted

