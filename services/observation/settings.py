"""Observation camera settings: where the camera is and what of its video goes on the bus."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, SecretStr

from common.lab_views import CameraConnection
from common.settings import NAME_PATTERN, ServiceSettings


class ObservationSettings(ServiceSettings):
    section = "observation"

    url: str = Field("http://127.0.0.1:8083", pattern=r"^https?://",
                     description="the camera's base URL (VAPIX: mjpg/video.cgi under it); the "
                     "sim's observation camera by default")
    user: str = "root"
    password: SecretStr = SecretStr("pass")
    auth: Literal["digest", "basic", "none"] = "digest"
    name: str = Field("observation", pattern=NAME_PATTERN,
                      description="the camera's name: its frames go on stb/video/<name>")
    fps: float = Field(5.0, gt=0, le=30, description="frames a second asked of the camera")
    resolution: str = Field("640x480", pattern=r"^[1-9][0-9]{1,4}x[1-9][0-9]{1,4}$",
                            description="the picture's size, as VAPIX names it")

    def connection(self) -> CameraConnection:
        return CameraConnection(url=self.url, user=self.user, password=self.password,
                                auth=self.auth)
