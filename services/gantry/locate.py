"""Where the robot is, from the crane's downward tracking camera (paper §3.1, eq. 5–8; pure).

The marker's pixel offset from the reference pixel (the point directly below the lens) is
scaled to millimetres on the ground by the thin-lens model: z is the distance from the lens
down to the marker, looked up in the crater's height map (the laser scan) at the marker's
position plus the marker's height above the ground; b follows from eq. 5. The marker's
position depends on z and z on the position, so the two are iterated (a few rounds settle to
well under a millimetre). Image axes: u grows with world +x, v with world −y (configurable).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from common.camera import thin_lens_image_distance_mm
from common.heightmap import HeightMap

ROUNDS = 4


@dataclass(frozen=True)
class TrackingOptics:
    focal_mm: float = 8.0
    pixel_mm: float = 0.0075  # d_x = d_y
    ref_u: float = 320.0
    ref_v: float = 240.0
    lens_height_mm: float = 3500.0  # above world z = 0
    u_sign: float = 1.0  # +1: u grows with world x
    v_sign: float = -1.0  # −1: v grows with world −y

    def scale(self, z_mm: float) -> float:
        """z / b (eq. 5–6): millimetres on the marker's plane per millimetre on the chip."""
        return z_mm / thin_lens_image_distance_mm(self.focal_mm, z_mm)


def offset_mm(u: float, v: float, z_mm: float, optics: TrackingOptics) -> np.ndarray:
    """(x_err, y_err) of eq. 7: the marker relative to the point below the lens."""
    k = optics.scale(z_mm) * optics.pixel_mm
    return np.array([optics.u_sign * (u - optics.ref_u) * k,
                     optics.v_sign * (v - optics.ref_v) * k])


def locate(u: float, v: float, crane_xy_mm: np.ndarray, optics: TrackingOptics,
           heights: HeightMap, marker_height_mm: float) -> np.ndarray:
    """The marker's world (x, y, z) from its pixel and the crane's position (eq. 5–8)."""
    xy = np.asarray(crane_xy_mm, dtype=float)
    for _ in range(ROUNDS):
        ground = float(heights.height_at(xy[0], xy[1]))
        z = optics.lens_height_mm - (ground + marker_height_mm)
        xy = np.asarray(crane_xy_mm, dtype=float) + offset_mm(u, v, z, optics)  # eq. 8
    ground = float(heights.height_at(xy[0], xy[1]))
    return np.array([xy[0], xy[1], ground + marker_height_mm])
