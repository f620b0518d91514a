"""Where the robot is, from the crane's downward tracking camera (paper §3.1, eq. 5–8; pure).

The marker's pixel is undistorted and turned into a direction from the lens through the
camera's lens and mount (``common.tracking_camera``: principal point, OpenCV's distortion, the
image's yaw against the crane's axes, the lens's offset from the crane's reported point), and
scaled to millimetres on the ground by the thin-lens model: z is the distance from the lens
down to the marker, looked up in the crater's height map (the laser scan) at the marker's
position plus the marker's height above the ground; b follows from eq. 5. The marker's
position depends on z and z on the position, so the two are iterated (a few rounds settle to
well under a millimetre). The crane's position comes in the world's coordinates (the crane's
frame is applied at the Modbus boundary, ``services/gantry/crane.py``).
"""

from __future__ import annotations

import numpy as np

from common.crane_frame import CraneFrame
from common.heightmap import HeightMap
from common.tracking_camera import TrackingCameraModel

ROUNDS = 4
SETTLED_MM = 0.05
"""Rounds stop once the position moves less than this (on flat ground after the second)."""


def locate(u: float, v: float, crane_xy_mm: np.ndarray, camera: TrackingCameraModel,
           frame: CraneFrame, heights: HeightMap, marker_height_mm: float) -> np.ndarray:
    """The marker's world (x, y, z) from its pixel and the crane's position in the world
    (eq. 5–8)."""
    lens = camera.lens_xy(crane_xy_mm, frame)
    xy = lens
    for _ in range(ROUNDS):
        ground = float(heights.height_at(float(xy[0]), float(xy[1])))
        z = camera.height_mm - (ground + marker_height_mm)
        moved = lens + camera.ground_offset(u, v, z, frame)  # eq. 7–8
        settled = abs(moved[0] - xy[0]) + abs(moved[1] - xy[1]) < SETTLED_MM
        xy = moved
        if settled:
            break
    ground = float(heights.height_at(float(xy[0]), float(xy[1])))
    return np.array([xy[0], xy[1], ground + marker_height_mm])
