"""The crane's downward tracking camera (paper §3.1): the paper's thin lens, OpenCV's lens
distortion, and how it hangs on the crane's carriage (pure). The sim renders its pictures
through it with its own truth of each value (``[sim.tracking_camera]``); the gantry locates
the robot through it with what commissioning measured (``[gantry.tracking_camera]``).

How it hangs. The lens is ``offset_mm`` from the crane's reported point, in the crane's own
frame (its axes and counting directions, ``common.crane_frame``), ``height_mm`` above the
world's z = 0, looking straight down. Image columns (u) grow along the crane's x axis and rows
(v) against its y axis (north up on the screen), both turned by ``yaw_deg`` against the
crane's axes (a flipped axis does not mirror the image: a flip is only how the crane counts).
So the camera frame is x_c along u, y_c along v, z_c down — right-handed.

Projection. A point at depth z below the lens, at (x_c, y_c) across, has normalised
coordinates (x_c / z, y_c / z); the lens bends them (OpenCV's k1, k2, p1, p2, k3:
``common.lens``); the chip is ``b(z)`` behind the lens (eq. 5, thin lens) with pixels
``pixel_mm`` wide, centred on ``principal_px``: u = c_x + b(z)/pixel · x_d.
"""

from __future__ import annotations

import math

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from common.crane_frame import CraneFrame
from common.lens import NO_DISTORTION, distort, undistort


class TrackingCameraModel(BaseModel):
    """The tracking camera's lens and mount; an ideal camera by default."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    focal_mm: float = Field(8.0, gt=0, le=200, description="the lens's focal length")
    pixel_mm: float = Field(0.0075, gt=0, le=0.1, description="pixel pitch (square pixels)")
    width_px: int = Field(640, ge=64, le=8192)
    height_px: int = Field(480, ge=64, le=8192)
    principal_px: tuple[float, float] | None = Field(
        None, description="where the optical axis meets the image (c_x, c_y): straight below "
        "the lens; none: the image's centre")
    distortion: tuple[float, float, float, float, float] = Field(
        NO_DISTORTION, description="OpenCV's k1, k2, p1, p2, k3")
    yaw_deg: float = Field(0.0, ge=-180, le=180, description="the image turned "
                           "counter-clockwise against the crane's axes, degrees")
    offset_mm: tuple[float, float] = Field((0.0, 0.0), description="the lens from the crane's "
                                           "reported point, in the crane's frame (mm)")
    height_mm: float = Field(3500.0, gt=0, description="the lens above the world's z = 0")

    @model_validator(mode="after")
    def _principal_point_in_the_image(self) -> TrackingCameraModel:
        cx, cy = self.principal
        if not (0 <= cx <= self.width_px and 0 <= cy <= self.height_px):
            raise ValueError(f"principal_px {self.principal_px} lies outside the "
                             f"{self.width_px} × {self.height_px} image")
        return self

    @property
    def principal(self) -> tuple[float, float]:
        """(c_x, c_y) in pixels."""
        if self.principal_px is None:
            return self.width_px / 2, self.height_px / 2
        return self.principal_px

    def lens_xy(self, crane_xy_world: np.ndarray, frame: CraneFrame) -> np.ndarray:
        """Where the lens is (world x, y) when the crane's reported point is at
        ``crane_xy_world``."""
        return np.asarray(crane_xy_world, dtype=float) + frame.vector_to_world(self.offset_mm)

    def image_axes(self, frame: CraneFrame) -> np.ndarray:
        """(2, 2): row 0 the world direction in which u grows, row 1 the one in which v
        grows."""
        a = math.radians(frame.yaw_deg + self.yaw_deg)
        c, s = math.cos(a), math.sin(a)
        return np.array([[c, s], [s, -c]])

    def chip_px(self, depth_mm: np.ndarray | float) -> np.ndarray:
        """b(z) / pixel: the lens-to-chip distance in pixels when focused at depth z (eq. 5,
        1/b = 1/f − 1/z); NaN at or inside the focal length."""
        if isinstance(depth_mm, float | int):
            if depth_mm <= self.focal_mm:
                return np.asarray(np.nan)
            return np.asarray(1.0 / (1.0 / self.focal_mm - 1.0 / depth_mm) / self.pixel_mm)
        depth = np.asarray(depth_mm, dtype=float)
        with np.errstate(divide="ignore", invalid="ignore"):
            b = 1.0 / (1.0 / self.focal_mm - 1.0 / depth)
        return np.where(depth > self.focal_mm, b, np.nan) / self.pixel_mm

    def project(self, points_world: np.ndarray, crane_xy_world: np.ndarray,
                frame: CraneFrame) -> tuple[np.ndarray, np.ndarray]:
        """Pixels (N, 2) of world points (N, 3), and each one's scale in px/mm at its depth;
        points at or above the lens give NaN."""
        points = np.atleast_2d(np.asarray(points_world, dtype=float))
        across = (points[:, :2] - self.lens_xy(crane_xy_world, frame)) @ self.image_axes(
            frame).T
        depth = self.height_mm - points[:, 2]
        valid = depth > 1.0
        depth = np.where(valid, depth, np.nan)
        bent = distort(across / depth[:, None], self.distortion)
        chip = self.chip_px(depth)
        pixels = np.asarray(self.principal) + bent * chip[:, None]
        return pixels, chip / depth

    def ray(self, u: float, v: float, depth_mm: float) -> np.ndarray:
        """The normalised undistorted direction (x_c / z, y_c / z) of pixel (u, v), for a
        point ``depth_mm`` below the lens (the thin lens's b depends on it, weakly)."""
        bent = (np.array([u, v]) - np.asarray(self.principal)) / self.chip_px(depth_mm)
        return undistort(bent, self.distortion)[0]

    def ground_offset(self, u: float, v: float, depth_mm: float, frame: CraneFrame
                      ) -> np.ndarray:
        """(x, y) in the world of the point at pixel (u, v), ``depth_mm`` below the lens,
        relative to the lens (eq. 7 with the lens's distortion and mount)."""
        return depth_mm * self.ray(u, v, depth_mm) @ self.image_axes(frame)
