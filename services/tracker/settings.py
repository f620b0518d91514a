"""Tracker settings: where QTM is, and how to tell the robot's marker."""

from __future__ import annotations

from pydantic import Field

from common.settings import ServiceSettings
from common.volume import Volume


class TrackerSettings(ServiceSettings):
    section = "tracker"

    qtm_host: str = "127.0.0.1"
    qtm_port: int = Field(22223, ge=1, le=65535, description="QTM RT little-endian port")
    frames: str = Field("allframes", pattern=r"^(allframes|frequency:\d+|frequencydivisor:\d+)$",
                        description="QTM stream rate: allframes, frequency:n, frequencydivisor:n")
    robot_label: str = Field("robot", description='label of the robot marker; "" = pick the '
                             "unidentified marker that moves")
    robot_body: str = Field("", max_length=64, description="QTM 6DOF body of the robot: its "
                            'origin and orientation instead of a marker; "" = use the marker')
    min_motion_mm: float = Field(15.0, gt=0, description="unlabelled: motion that marks the robot")
    velocity_window_s: float = Field(0.1, gt=0)
    volume: Volume = Field(Volume(), description="robot positions outside are ignored (mm)")
