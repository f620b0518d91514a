"""Router settings: where it listens, other routers, authentication, TLS, access control."""

from __future__ import annotations

from pathlib import Path

from pydantic import Field

from common.settings import ServiceSettings, TlsSettings, ZenohSettings

DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"


class RouterSettings(ServiceSettings):
    section = "router"

    listen: list[str] | None = Field(
        None, description=f"endpoints; default: the config file's, else {DEFAULT_ENDPOINT}")
    connect: list[str] = Field(default_factory=list, description="other routers to link with")
    config_file: Path | None = Field(
        None, description="Zenoh JSON5/YAML config (access control, ...), as eclipse/zenoh reads")
    users_file: Path | None = Field(None, description="'user:password' lines for usrpwd auth")
    tls: TlsSettings = TlsSettings()

    def zenoh_settings(self) -> ZenohSettings:
        """The router's own Zenoh settings (the shared ``bus.zenoh`` is for clients)."""
        default = [] if self.config_file else [DEFAULT_ENDPOINT]
        return ZenohSettings(
            mode="router", listen=self.listen if self.listen is not None else default,
            connect=self.connect, config_file=self.config_file, users_file=self.users_file,
            tls=self.tls, lease_ms=self.bus.zenoh.lease_ms,
            multicast_scouting=self.bus.zenoh.multicast_scouting)
