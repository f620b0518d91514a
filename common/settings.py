"""Settings of every service: one lab config file plus environment variables, validated once.

Precedence, lowest first: defaults < the lab file (``[bus]`` for everyone, a field another
section names for the whole lab (``borrowed``: the crater's ``[gantry] height_map``), then the
service's own ``[<section>]`` table) < environment (``STB_BUS__<FIELD>`` for everyone, then
``STB_<SECTION>__<FIELD>``; nested fields with ``__``; lists and tables as JSON) < command-line
overrides. With no configuration at all a service runs against the simulator on loopback.

Settings are plain pydantic models and ``load_settings`` is their loader: pydantic-settings'
sources take one environment prefix per model and read a TOML file whole, while this
precedence merges the shared ``[bus]`` table and ``STB_BUS__*`` into every service's settings
beside its own section; sources of our own for that would be longer than the loader.
"""

from __future__ import annotations

import json
import os
import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any, ClassVar, Literal, TypeVar

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    SecretStr,
    ValidationError,
    ValidationInfo,
    field_validator,
    model_validator,
)

from common.errors import ConfigError
from common.keys import DEFAULT_PREFIX, check_prefix
from common.setting_text import setting_value

S = TypeVar("S", bound="ServiceSettings")
NAME_PATTERN = r"^[A-Za-z0-9_.-]{1,64}$"
"""A name in a lab file that goes into key expressions and identities: an instance, a camera,
a user (the bus's ``Name``, common/messages.py)."""

CONFIG_ENV = "STB_LAB"
LogLevel = Literal["DEBUG", "INFO", "WARNING", "ERROR"]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class TlsSettings(_Strict):
    """TLS for links to the router (``tls/`` endpoints); paths to PEM files."""

    root_ca_certificate: Path | None = None
    certificate: Path | None = Field(None, description="own certificate (router: listen side)")
    private_key: Path | None = None
    enable_mtls: bool = False
    verify_name_on_connect: bool = True


class ZenohSettings(_Strict):
    """How a node joins the Zenoh network."""

    mode: Literal["client", "peer", "router"] = "client"
    connect: list[str] = Field(default_factory=lambda: ["tcp/127.0.0.1:7447"])
    listen: list[str] = Field(default_factory=list)
    multicast_scouting: bool = False
    user: str | None = Field(None, pattern=NAME_PATTERN, description="the "
                             "router's user name: this node's identity on the bus")
    password: SecretStr | None = None
    password_file: Path | None = Field(
        None, description="read the password from this file (a Docker secret), not the config")
    users_file: Path | None = Field(None, description="router only: 'user:password' lines")
    tls: TlsSettings = TlsSettings()
    config_file: Path | None = Field(
        None, description="a Zenoh JSON5/YAML config applied first (e.g. access control)"
    )
    lease_ms: int = Field(2000, ge=200, description="how soon peers notice that we are gone")
    connect_timeout_ms: int = Field(
        10_000, ge=-1, description="client start-up: wait this long for a router (-1: forever)"
    )
    retry_init_ms: int = Field(100, ge=10)
    retry_max_ms: int = Field(500, ge=10)
    shm_pool_mib: float = Field(
        4.0, gt=0, description="the shared-memory pool a node sends its large messages (over "
        "3 kB) to other processes of its host through; every receiver maps each sender's pool "
        "(Zenoh's default, 16 MiB, held 64 MiB in the router alone). 4 MiB holds 13 of the "
        "largest message, the tracking camera's 307 kB frame (docs/benchmarks.md, Memory)")

    @field_validator("connect", "listen")
    @classmethod
    def _endpoints_look_right(cls, endpoints: list[str]) -> list[str]:
        for endpoint in endpoints:
            proto, sep, addr = endpoint.partition("/")
            if not sep or not proto or not addr:
                raise ValueError(f"endpoint {endpoint!r} is not '<proto>/<address>:<port>'")
        return endpoints

    def identity(self, default: str) -> str:
        """Who this node is on the bus: its user (the router's access control knows it), else
        ``default`` (an open bus, where nothing checks it)."""
        return self.user or default

    @model_validator(mode="after")
    def _password_file_is_readable(self) -> ZenohSettings:
        if self.password_file is not None:
            if self.password is not None:
                raise ValueError("give password or password_file, not both")
            self.secret()
        return self

    def secret(self) -> str | None:
        """The password, from the settings or from ``password_file``."""
        if self.password is not None:
            return self.password.get_secret_value()
        if self.password_file is None:
            return None
        try:
            secret = self.password_file.read_text().strip()
        except OSError as err:
            raise ValueError(f"password_file {self.password_file}: {err.strerror}") from err
        if not secret:
            raise ValueError(f"password_file {self.password_file} is empty")
        return secret


class BusSettings(_Strict):
    """Key prefix, input limits and the Zenoh link, shared by every service of a lab."""

    prefix: str = DEFAULT_PREFIX
    max_age_s: float = Field(
        0.5, gt=0, description="stream samples older than this are dropped (needs synced clocks)"
    )
    max_future_s: float = Field(0.5, gt=0, description="tolerated clock skew into the future")
    health_period_s: float = Field(1.0, gt=0)
    zenoh: ZenohSettings = ZenohSettings()

    @field_validator("prefix")
    @classmethod
    def _prefix_is_a_key(cls, prefix: str) -> str:
        return check_prefix(prefix)


class ServiceSettings(BaseModel):
    """Base of every service's settings; subclasses set ``section`` and add their fields."""

    model_config = ConfigDict(extra="forbid", frozen=True, validate_default=True)
    section: ClassVar[str] = "service"
    borrowed: ClassVar[dict[str, str]] = {}
    """Fields that another section names for the whole lab: field → that section (e.g. the
    crater's height map, ``[gantry] height_map``, which the page and the recorders draw).
    Taken from there when the service's own section does not set it."""

    instance: str = Field("main", pattern=NAME_PATTERN)
    log_level: LogLevel = "INFO"
    realtime_priority: int = Field(
        0, ge=0, le=99, description="SCHED_FIFO priority 1-99 for this service's threads, so "
        "that it reacts at once on a busy machine (needs an rtprio limit or CAP_SYS_NICE); 0 = "
        "normal scheduling")
    bus: BusSettings = BusSettings()

    def zenoh_settings(self) -> ZenohSettings:
        """How this service joins the bus (the router overrides this)."""
        return self.bus.zenoh


def load_settings(
    cls: type[S],
    config_file: Path | None = None,
    overrides: Mapping[str, Any] | None = None,
    environ: Mapping[str, str] | None = None,
) -> S:
    """Build ``cls`` from the lab file, the environment and ``overrides``; see module doc."""
    environ = os.environ if environ is None else environ
    if config_file is None and environ.get(CONFIG_ENV):
        config_file = Path(environ[CONFIG_ENV])
    merged: dict[str, Any] = {}
    if config_file is not None:
        lab = read_lab_file(config_file)
        _deep_merge(merged, {"bus": lab.get("bus", {})})
        own = lab.get(cls.section, {})
        for name, section in cls.borrowed.items():
            other = lab.get(section, {})
            if isinstance(other, dict) and name in other and name not in own:
                merged[name] = other[name]
        _deep_merge(merged, own)
    _deep_merge(merged, {"bus": _env("STB_BUS__", environ)})
    _deep_merge(merged, _env(f"STB_{cls.section.upper()}__", environ))
    _deep_merge(merged, dict(overrides or {}))
    try:
        return cls(**merged)
    except ValidationError as err:
        raise ConfigError(describe_errors(err, cls.section, config_file)) from None


def read_lab_file(path: Path) -> dict[str, Any]:
    """The lab file as a dict; ConfigError if it is missing or not TOML."""
    try:
        with open(path, "rb") as f:
            return tomllib.load(f)
    except OSError as err:
        raise ConfigError(f"cannot read lab config {path}: {err.strerror}") from None
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"lab config {path} is not valid TOML: {err}") from None
    except UnicodeDecodeError as err:
        raise ConfigError(f"lab config {path} is not valid TOML: not UTF-8 text (byte "
                          f"{err.start})") from None


def above_its_minimum(value: float, info: ValidationInfo) -> float:
    """A field validator for an interval's upper end ``*_max*``: it must lie above the
    matching ``*_min*`` field (declared before it)."""
    assert info.field_name is not None
    lower = info.field_name.replace("_max", "_min")
    low = info.data.get(lower)
    if low is not None and not value > low:
        raise ValueError(f"must be greater than {lower} ({low:g})")
    return value


def describe_errors(err: ValidationError, section: str, config_file: Path | None) -> str:
    where = f"[{section}] of {config_file}" if config_file else "the defaults"
    lines = [f"invalid {section} settings (from {where}, STB_{section.upper()}__* or flags):"]
    for e in err.errors():
        field = ".".join(str(p) for p in e["loc"]) or "<settings>"
        got = "" if e["type"] == "missing" else f" (got {e.get('input')!r})"
        lines.append(f"  {section}.{field}: {e['msg']}{got}")
    return "\n".join(lines)


def bus_environment(bus: BusSettings) -> dict[str, str]:
    """The environment (``STB_BUS__*``) that gives a child process this bus: the same prefix,
    router, identity and TLS (a password as itself, from the settings or its file)."""
    values = bus.model_dump(mode="json", exclude_none=True, exclude={"zenoh": {"password"}})
    secret = bus.zenoh.secret() if bus.zenoh.password is not None else None
    if secret is not None:
        values["zenoh"]["password"] = secret
    out: dict[str, str] = {}

    def flatten(prefix: str, value: Any) -> None:
        if isinstance(value, dict):
            for key, inner in value.items():
                flatten(f"{prefix}__{key.upper()}", inner)
        else:
            out[prefix] = value if isinstance(value, str) else json.dumps(value)

    flatten("STB_BUS", values)
    return out


def _env(prefix: str, environ: Mapping[str, str]) -> dict[str, Any]:
    """Nested dict from variables ``<prefix>A__B=value``; values starting with [ { " are JSON."""
    out: dict[str, Any] = {}
    for name, value in environ.items():
        if not name.upper().startswith(prefix):
            continue
        *parents, leaf = name[len(prefix):].lower().split("__")
        target = out
        for parent in parents:
            target = target.setdefault(parent, {})
        target[leaf] = setting_value(value)
    return out


def _deep_merge(into: dict[str, Any], new: Mapping[str, Any]) -> dict[str, Any]:
    for key, value in new.items():
        if isinstance(value, Mapping) and isinstance(into.get(key), dict):
            _deep_merge(into[key], value)
        else:
            into[key] = dict(value) if isinstance(value, Mapping) else value
    return into
