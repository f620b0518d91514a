"""Web page settings: where it listens and what it draws the crater from."""

from __future__ import annotations

from pathlib import Path

from pydantic import Field

from common.settings import ServiceSettings


class WebSettings(ServiceSettings):
    section = "web"

    host: str = Field("127.0.0.1", description="address to listen on; 0.0.0.0 for the lab LAN")
    port: int = Field(8080, ge=0, le=65535)
    height_map: Path | None = Field(Path("run/sim/crater.npz"),
                                    description="crater height map (.npz) drawn under the "
                                    "tracks; missing file: a plain grid")
    track_s: float = Field(60.0, gt=0, le=3600, description="robot track shown, seconds")
    history_s: float = Field(300.0, gt=0, le=3600, description="crane error and sideways "
                             "pull plotted, seconds")
    push_hz: float = Field(5.0, gt=0, le=30, description="page updates a second")
