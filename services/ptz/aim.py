"""Where to point a PTZ camera (paper §2.3, eq. 4): a target in camera coordinates → pan, tilt.

Camera coordinates are those of the calibrated pose at pan = tilt = 0 (``common.camera``):
x along the optical axis, y to the right, z down. Positive pan turns right, positive tilt up.
Pure: no I/O, no clock.
"""

from __future__ import annotations

import math

import numpy as np

from common.camera import Pose, PtzLimits
from common.ptz_lens import PtzLens

DEFAULT_LIMITS = PtzLimits()
STRAIGHT_LENS = PtzLens()
"""The limits used where a camera has not reported its own (±170° pan, ±90° tilt, zoom 1–9999)."""


def pan_tilt(x: float, y: float, z: float, *, current_pan_deg: float = 0.0,
             current_tilt_deg: float = 0.0) -> tuple[float, float]:
    """Eq. 4: pan in (−180°, 180°], tilt in [−90°, 90°] for a target at camera (x, y, z).

    Special cases: on the vertical axis (x = y = 0) the pan is free, so the current pan is
    kept (no needless swing) and the tilt is ±90° by the sign of z; at the origin itself
    nothing is defined and the current position is kept.
    """
    if not all(math.isfinite(c) for c in (x, y, z)):
        raise ValueError(f"target ({x}, {y}, {z}) is not finite")
    horizontal = math.hypot(x, y)
    if horizontal == 0.0:
        if z == 0.0:
            return current_pan_deg, current_tilt_deg
        return current_pan_deg, -90.0 if z > 0 else 90.0
    tilt = -math.degrees(math.atan(z / horizontal)) + 0.0  # + 0.0: no "-0.0"
    pan = math.degrees(math.acos(max(-1.0, min(1.0, x / horizontal))))
    if y < 0 and pan < 180.0:  # (−180°, 180°]: straight behind is +180°
        pan = -pan
    return pan, tilt


def within_limits(pan_deg: float, tilt_deg: float, limits: PtzLimits) -> tuple[float, float]:
    """Clamp to what the camera can reach."""
    pan, tilt, _ = limits.clamp(pan_deg, tilt_deg, limits.min_zoom)
    return pan, tilt


def aim_at(target_world: np.ndarray, pose: Pose, limits: PtzLimits = DEFAULT_LIMITS, *,
           current_pan_deg: float = 0.0, current_tilt_deg: float = 0.0
           ) -> tuple[float, float]:
    """Pan and tilt (deg, within the limits) that put a world point (mm) on the optical axis."""
    x, y, z = pose.to_camera(np.asarray(target_world, dtype=float)[None, :])[0]
    pan, tilt = pan_tilt(float(x), float(y), float(z), current_pan_deg=current_pan_deg,
                         current_tilt_deg=current_tilt_deg)
    return within_limits(pan, tilt, limits)


def optical_axis(pan_deg: float, tilt_deg: float) -> np.ndarray:
    """Unit vector of the optical axis in camera-at-home coordinates (inverse of eq. 4)."""
    pan, tilt = math.radians(pan_deg), math.radians(tilt_deg)
    return np.array([math.cos(tilt) * math.cos(pan), math.cos(tilt) * math.sin(pan),
                     -math.sin(tilt)])


def aim_error_deg(target_world: np.ndarray, pose: Pose, pan_deg: float,
                  tilt_deg: float) -> float:
    """Angle between where the camera looks and where the target is."""
    direction = pose.to_camera(np.asarray(target_world, dtype=float)[None, :])[0]
    norm = float(np.linalg.norm(direction))
    if norm == 0.0:
        return 0.0
    cosine = float(optical_axis(pan_deg, tilt_deg) @ direction) / norm
    return math.degrees(math.acos(max(-1.0, min(1.0, cosine))))


def zoom_for_size(distance_mm: float, *, object_mm: float, image_fraction: float,
                  limits: PtzLimits = DEFAULT_LIMITS, lens: PtzLens = STRAIGHT_LENS) -> int:
    """Zoom step that makes an object of ``object_mm`` fill ``image_fraction`` of the image
    height at ``distance_mm`` (beyond the paper: constant apparent size), read off the
    lens's zoom curve (measured, or the data sheet's straight line)."""
    if distance_mm <= 0 or object_mm <= 0 or not 0 < image_fraction <= 1:
        raise ValueError("distance, object size and image fraction must be positive")
    half_view = math.degrees(math.atan(object_mm / image_fraction / 2 / distance_mm))
    zoom = lens.zoom_for_view(half_view)
    return int(min(max(zoom, limits.min_zoom), limits.max_zoom))


def predict(position_mm: np.ndarray, velocity_mm_s: np.ndarray, ahead_s: float,
            max_ahead_s: float = 0.5) -> np.ndarray:
    """Where the robot will be ``ahead_s`` from its measurement (bounded extrapolation), to
    make up for the camera's command latency."""
    ahead = min(max(ahead_s, 0.0), max_ahead_s)
    return np.asarray(position_mm, float) + ahead * np.asarray(velocity_mm_s, float)


