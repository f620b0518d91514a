"""Camera settings: which camera, how its frames travel."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from common.settings import NAME_PATTERN, ServiceSettings


class CameraSettings(ServiceSettings):
    section = "camera"

    source: str = Field("0", description='OpenCV source: a device number ("0") or a stream '
                        'URL ("rtsp://…", a video file)')
    name: str = Field("tracking", pattern=NAME_PATTERN,
                      description="the camera's name in each frame")
    encoding: Literal["mono8", "jpeg"] = Field(
        "mono8", description="mono8: raw gray pixels (640×480: 300 kB a frame, what the "
        "detector was measured on); jpeg: about a tenth of that")
    jpeg_quality: int = Field(95, ge=50, le=100)
    max_rate_hz: float = Field(30.0, gt=0, le=200, description="frames a second at most")
    exposure_ms: float | None = Field(
        None, gt=0, le=1000, description="the camera's exposure time, auto exposure off (V4L2 "
        "devices through OpenCV); none: the camera's own. The paper lowers it until only the "
        "IR marker is left: the shortest at which the marker still saturates "
        "(docs/benchmarks.md, \"Exposure\")")
