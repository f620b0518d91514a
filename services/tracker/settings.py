"""Tracker settings: where QTM is, and how to tell the robot's marker."""

from __future__ import annotations

from pydantic import Field

from common.settings import ServiceSettings


class TrackerSettings(ServiceSettings):
    section = "tracker"

    qtm_host: str = "127.0.0.1"
    qtm_port: int = Field(22223, ge=1, le=65535, description="QTM RT little-endian port")
    frames: str = Field("allframes", pattern=r"^(allframes|frequency:\d+|frequencydivisor:\d+)$",
                        description="QTM stream rate: allframes, frequency:n, frequencydivisor:n")
    robot_label: str = Field("robot", description='label of the robot marker; "" = pick the '
                             "unidentified marker that moves")
    min_motion_mm: float = Field(15.0, gt=0, description="unlabelled: motion that marks the robot")
    velocity_window_s: float = Field(0.1, gt=0)
    x_min_mm: float = -5000.0
    x_max_mm: float = 5000.0
    y_min_mm: float = -5000.0
    y_max_mm: float = 5000.0
    z_min_mm: float = -1000.0
    z_max_mm: float = 4000.0
