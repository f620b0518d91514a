"""What tools read of another service's lab-file section, defined once here so that no tool
imports a service: the PTZ cameras and how to reach them (``[ptz] cameras``, which the PTZ
services, ``stb record --video`` and the recording's video read), where the crater's height
map is (``[gantry] height_map``, read by the gantry, the page, Foxglove, recordings and
``stb report``) and the sim's own crater (``[sim] crater_file``, for ``stb up``'s first
start). A view reads its fields of a section and leaves the rest to the service that owns
it."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, ClassVar, Literal

from pydantic import BaseModel, ConfigDict, Field, SecretStr

from common.lab_paths import DEFAULT_HEIGHT_MAP, SIM_CRATER_FILE
from common.settings import ServiceSettings

if TYPE_CHECKING:  # httpx is imported where a camera is reached, not by tools that only read
    import httpx

CameraAuth = Literal["digest", "basic", "none"]
PAPER_MARKER_MM = 19.0
"""The robot's reflective marker's diameter in the paper (§3.1: "a diameter of 19 mm"): the
default of ``[ptz] robot_marker_mm``."""


class CameraConnection(BaseModel):
    """How to reach one AXIS PTZ camera (VAPIX over HTTP)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    url: str = Field(pattern=r"^https?://")
    user: str = "root"
    password: SecretStr = SecretStr("pass")
    auth: CameraAuth = "digest"

    def http_auth(self) -> httpx.Auth | None:
        return http_auth(self.user, self.password.get_secret_value(), self.auth)


def http_auth(user: str, password: str, auth: CameraAuth) -> httpx.Auth | None:
    """How an AXIS camera is signed in to: Digest (its default), Basic, or not at all."""
    import httpx

    if auth == "digest":
        return httpx.DigestAuth(user, password)
    if auth == "basic":
        return httpx.BasicAuth(user, password)
    return None


def default_cameras() -> dict[str, CameraConnection]:
    """The sim's two cameras on this machine."""
    return {"ptz1": CameraConnection(url="http://127.0.0.1:8081"),
            "ptz2": CameraConnection(url="http://127.0.0.1:8082")}


class LabCameras(ServiceSettings):
    """``[ptz] cameras`` alone (the rest of ``[ptz]`` is the PTZ service's)."""

    model_config = ConfigDict(extra="ignore", frozen=True, validate_default=True)
    section: ClassVar[str] = "ptz"

    cameras: dict[str, CameraConnection] = Field(default_factory=default_cameras)


class GantryHeightMap(ServiceSettings):
    """``[gantry] height_map`` alone (the rest of ``[gantry]`` is the gantry's)."""

    model_config = ConfigDict(extra="ignore", frozen=True, validate_default=True)
    section: ClassVar[str] = "gantry"

    height_map: Path = DEFAULT_HEIGHT_MAP


class SimCraterFile(ServiceSettings):
    """``[sim] crater_file`` alone: the sim's own crater (its truth)."""

    model_config = ConfigDict(extra="ignore", frozen=True, validate_default=True)
    section: ClassVar[str] = "sim"

    crater_file: Path = SIM_CRATER_FILE
