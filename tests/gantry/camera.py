"""The tracking camera the gantry's tests draw frames with: the ideal one, through the model
the sim renders with (``common.tracking_camera``)."""

from __future__ import annotations

import numpy as np

from common.crane_frame import CRANE_COUNTS_IN_THE_WORLD, CraneFrame
from common.tracking_camera import TrackingCameraModel
from services.sim.render import MARKER_RADIUS_MM

CAMERA = TrackingCameraModel(focal_mm=8.0, pixel_mm=0.0075, height_mm=3500.0)


def pixel_of(point_world: np.ndarray, crane_xy: np.ndarray,
             camera: TrackingCameraModel = CAMERA,
             frame: CraneFrame = CRANE_COUNTS_IN_THE_WORLD) -> tuple[float, float, float]:
    """(u, v, radius_px) of a marker at ``point_world`` seen from the crane at ``crane_xy``."""
    pixels, scale = camera.project(point_world, crane_xy, frame)
    return float(pixels[0, 0]), float(pixels[0, 1]), float(MARKER_RADIUS_MM * scale[0])
