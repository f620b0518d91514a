"""A PTZ head as an AXIS 215 PTZ moves (pure, on an injected time; no clock, no sleeping).

Commands take effect ``latency_s`` after they arrive; pan and tilt then move at finite speed
(scaled by the VAPIX ``speed`` 1…100) towards their target, or at a rate in continuous mode,
and stop at the limits. Zoom moves in steps per second.

The head's own geometry (the sim's truth, never read by a service): the pan axis is the
mount's z axis through the mount's position; the tilt axis is parallel to the panned head's
y axis through ``tilt_axis_mm`` (in the panned head's frame); the lens's optical centre is at
``optical_centre_mm`` from that point in the camera's frame (x along the view). A real head's
axes need not meet, nor the optical centre sit on them; with both zero they do, which is
what the PTZ service's model assumes (``common.camera.head_pose``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from common.camera import Intrinsics, Pose, PtzLimits, rot_y, rot_z
from common.ptz_lens import PtzLens


@dataclass
class _Axis:
    position: float
    target: float
    rate: float = 0.0  # continuous mode: signed units/s; 0 = move to target
    speed: float = 1.0  # fraction of the maximum speed for target moves

    def advance(self, dt: float, max_speed: float, lo: float, hi: float) -> None:
        if self.rate:
            self.position = min(max(self.position + self.rate * dt, lo), hi)
            self.target = self.position
            return
        step = max_speed * self.speed * dt
        error = self.target - self.position
        self.position = self.target if abs(error) <= step else self.position + np.sign(error) * step


@dataclass
class PtzHead:
    """The moving part of a simulated PTZ camera; ``mount`` is its pose at pan = tilt = 0."""

    mount: Pose
    lens: PtzLens = PtzLens()  # its truth: zoom curve and distortion
    limits: PtzLimits = PtzLimits()
    pan_speed_deg_s: float = 100.0
    tilt_speed_deg_s: float = 90.0
    zoom_steps_s: float = 4000.0
    latency_s: float = 0.12
    ir_cut_filter: str = "auto"
    ir_cut_moves: int = 0  # how often the filter moved in or out (a mechanical switch)
    tilt_axis_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)
    optical_centre_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)
    _time: float = 0.0
    _pan: _Axis = field(default_factory=lambda: _Axis(0.0, 0.0))
    _tilt: _Axis = field(default_factory=lambda: _Axis(0.0, 0.0))
    _zoom: _Axis = field(default_factory=lambda: _Axis(1.0, 1.0))
    _pending: list[tuple[float, str, tuple]] = field(default_factory=list)

    # --- commands (take effect after the latency) -----------------------------------------

    def set_ir_cut_filter(self, mode: str) -> None:
        """VAPIX ``ircutfilter``: on, off or auto (the sim's lab is lit: auto keeps it in)."""
        if (mode == "off") != (self.ir_cut_filter == "off"):
            self.ir_cut_moves += 1
        self.ir_cut_filter = mode

    def absolute(self, now: float, pan: float | None = None, tilt: float | None = None,
                 zoom: float | None = None, speed: float | None = None) -> None:
        self._queue(now, "absolute", (pan, tilt, zoom, speed))

    def relative(self, now: float, rpan: float = 0.0, rtilt: float = 0.0, rzoom: float = 0.0,
                 speed: float | None = None) -> None:
        self._queue(now, "relative", (rpan, rtilt, rzoom, speed))

    def continuous(self, now: float, pan_pct: float | None = None, tilt_pct: float | None = None,
                   zoom_pct: float | None = None) -> None:
        self._queue(now, "continuous", (pan_pct, tilt_pct, zoom_pct))

    def stop(self, now: float) -> None:
        self._queue(now, "stop", ())

    def _queue(self, now: float, kind: str, args: tuple) -> None:
        self.advance_to(now)
        self._pending.append((now + self.latency_s, kind, args))

    # --- state ------------------------------------------------------------------------------

    def state(self, now: float) -> tuple[float, float, int, bool]:
        """(pan_deg, tilt_deg, zoom, moving) at ``now``."""
        self.advance_to(now)
        moving = any(a.rate or a.position != a.target for a in (self._pan, self._tilt, self._zoom))
        return self._pan.position, self._tilt.position, int(round(self._zoom.position)), moving

    def pose(self, now: float) -> Pose:
        """Where the camera is and looks at ``now``."""
        pan, tilt, _, _ = self.state(now)
        return self.pose_at(pan, tilt)

    def pose_at(self, pan_deg: float, tilt_deg: float) -> Pose:
        """The camera's pose at this pan and tilt: turned about the pan axis (the mount's z,
        positive turns right), then about the tilt axis (the panned y, positive turns up),
        with the tilt axis and the optical centre where this head has them."""
        panned = self.mount.rotation @ rot_z(np.radians(pan_deg))
        camera = panned @ rot_y(np.radians(tilt_deg))
        centre = (self.mount.position + panned @ np.asarray(self.tilt_axis_mm, float)
                  + camera @ np.asarray(self.optical_centre_mm, float))
        return Pose.from_matrix(camera, centre)

    def focal_px(self, now: float) -> float:
        """Its focal length at the zoom of ``now``, in pixels of its own picture."""
        return self.lens.focal_px(self.state(now)[2])

    def intrinsics(self, now: float, width_px: int | None = None, height_px: int | None = None
                   ) -> Intrinsics:
        """Its lens at the zoom of ``now``, for a picture of this size (default its full
        picture)."""
        return self.lens.intrinsics(self.state(now)[2], width_px, height_px)

    def advance_to(self, now: float) -> None:
        if now < self._time:
            return
        while self._pending and self._pending[0][0] <= now:
            at, kind, args = self._pending.pop(0)
            self._move(at)
            self._apply(kind, args)
        self._move(now)

    def _move(self, now: float) -> None:
        dt = max(0.0, now - self._time)
        lim = self.limits
        self._pan.advance(dt, self.pan_speed_deg_s, lim.min_pan, lim.max_pan)
        self._tilt.advance(dt, self.tilt_speed_deg_s, lim.min_tilt, lim.max_tilt)
        self._zoom.advance(dt, self.zoom_steps_s, lim.min_zoom, lim.max_zoom)
        self._time = max(self._time, now)

    def _apply(self, kind: str, args: tuple) -> None:
        axes = (self._pan, self._tilt, self._zoom)
        if kind == "stop":
            for axis in axes:
                axis.rate, axis.target = 0.0, axis.position
            return
        if kind == "continuous":
            maxima = (self.pan_speed_deg_s, self.tilt_speed_deg_s, self.zoom_steps_s)
            for axis, pct, top in zip(axes, args, maxima, strict=True):
                if pct is not None:
                    axis.rate = top * pct / 100.0
            return
        *values, speed = args
        if kind == "relative":
            values = [a.position + v for a, v in zip(axes, values, strict=True)]
        current = [a.position if v is None else v for a, v in zip(axes, values, strict=True)]
        pan, tilt, zoom = self.limits.clamp(*current)
        for axis, target in zip(axes, (pan, tilt, zoom), strict=True):
            axis.rate, axis.target = 0.0, target
            axis.speed = 1.0 if speed is None else min(max(speed, 1.0), 100.0) / 100.0
