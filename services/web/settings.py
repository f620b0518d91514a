"""Web page settings: where it listens, who may sign in, TLS, and what it draws the crater
from."""

from __future__ import annotations

import ipaddress
from pathlib import Path
from typing import Annotated

from pydantic import Field, model_validator

from common.lab_paths import DEFAULT_HEIGHT_MAP
from common.settings import ServiceSettings


class WebSettings(ServiceSettings):
    section = "web"
    borrowed = {"height_map": "gantry"}  # the lab's crater, named once

    host: str = Field("127.0.0.1", description="address to listen on; 0.0.0.0 for the lab LAN "
                      "(needs users_file)")
    port: int = Field(8080, ge=0, le=65535)
    users_file: Path | None = Field(
        None, description="who may sign in (stb web user add NAME --role operator|viewer); "
        "without one the page serves loopback only, everyone on this machine as operator")
    tls_certificate: Path | None = Field(None, description="PEM certificate: serve https")
    tls_key: Path | None = Field(None, description="PEM private key of tls_certificate")
    session_h: float = Field(12.0, gt=0, le=24 * 30, description="a sign-in lasts this long, "
                             "hours")
    server_names: list[Annotated[str, Field(max_length=253)]] = Field(
        default_factory=list, max_length=64, description="host names the lab's browsers "
        "reach the page by, beside IP addresses, localhost and this machine's own names; a "
        "request for any other name (Host) is refused 421 (DNS rebinding)")
    trusted_proxies: list[Annotated[str, Field(max_length=64)]] = Field(
        default_factory=list, max_length=32, description="addresses of reverse proxies whose "
        "X-Forwarded-For names the client (for the sign-in brake and the audit); from any "
        "other sender, loopback included, the header is ignored")
    max_streams: int = Field(50, ge=1, le=10_000, description="open live views (event "
                             "streams) at once; more are refused until one closes")
    recordings_dir: Path = Field(Path("run/recordings"), description="where the page's "
                                 "recordings (stb record) and their reports go")
    calibration_count: int = Field(100, ge=6, le=10_000, description="passpoints a calibration "
                                   "started from the page collects")
    height_map: Path | None = Field(DEFAULT_HEIGHT_MAP,
                                    description="crater height map (.npz) drawn under the "
                                    "tracks ([gantry] height_map unless set here); missing "
                                    "file: a plain grid")
    track_s: float = Field(60.0, gt=0, le=3600, description="robot track shown, seconds")
    history_s: float = Field(300.0, gt=0, le=3600, description="crane error and sideways "
                             "pull plotted, seconds")
    push_hz: float = Field(5.0, gt=0, le=30, description="page updates a second")

    @model_validator(mode="after")
    def _safe_to_serve(self) -> WebSettings:
        if (self.tls_certificate is None) != (self.tls_key is None):
            raise ValueError("tls_certificate and tls_key go together: give both or neither")
        if self.users_file is None and not is_loopback(self.host):
            raise ValueError(
                f"host {self.host!r} reaches beyond this machine, and there is no users_file: "
                "anyone on the network could move the crane. Add users (stb web user add NAME "
                "--role operator --users FILE) and set users_file, or keep host = 127.0.0.1")
        return self

    @property
    def tls(self) -> tuple[Path, Path] | None:
        if self.tls_certificate is None or self.tls_key is None:
            return None
        return self.tls_certificate, self.tls_key


def is_loopback(host: str) -> bool:
    """Whether ``host`` is reachable only from this machine (127.x, ::1, localhost)."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False
