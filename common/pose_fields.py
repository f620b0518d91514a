"""The six numbers of a camera's pose T_world_camera (paper eq. 1: R = Rx·Ry·Rz, the x axis
along the optical axis), named once: the calibration's ``CameraPose`` message and the sim's
camera truth (``[[sim.cameras]]``) take their fields from here, and ``common.camera.Pose`` is
read from and written to them."""

from __future__ import annotations

from pydantic import BaseModel, Field


class PoseFields(BaseModel):
    """Where a camera is (mm, world frame) and how it is turned (degrees, R = Rx·Ry·Rz)."""

    x_mm: float = Field(description="the camera's position in the world, mm")
    y_mm: float
    z_mm: float
    rx_deg: float = Field(description="its rotation, R = Rx·Ry·Rz, degrees")
    ry_deg: float
    rz_deg: float


POSE_FIELDS: tuple[str, ...] = tuple(PoseFields.model_fields)
"""x_mm, y_mm, z_mm, rx_deg, ry_deg, rz_deg"""
