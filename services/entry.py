"""The command line every service shares: ``--lab FILE``, ``--instance``, ``--set k=v``."""

from __future__ import annotations

import argparse
import json
import logging
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, TypeVar

import zenoh

from common.bus import BusUnreachable, open_session
from common.node import EXIT_UNREACHABLE, Node, configure_logging, run_node
from common.settings import ConfigError, ServiceSettings, load_settings

S = TypeVar("S", bound=ServiceSettings)
EXIT_CONFIG = 2

log = logging.getLogger(__name__)


def base_parser(prog: str, description: str) -> argparse.ArgumentParser:
    """A command's parser with the common flags; ``description`` (a module docstring) is
    shown as written, its RST literals as plain text."""
    parser = argparse.ArgumentParser(prog=prog, description=plain(description),
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--lab", type=Path, metavar="FILE",
                        help="lab config file (TOML); default: $STB_LAB, else built-in defaults")
    parser.add_argument("--instance", help="instance name (default: from config, else 'main')")
    parser.add_argument("--connect", action="append", metavar="ENDPOINT",
                        help="router endpoint, e.g. tcp/10.0.0.2:7447 (repeatable)")
    parser.add_argument("--log-level", choices=["DEBUG", "INFO", "WARNING", "ERROR"])
    parser.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                        help="override one setting, e.g. --set bus.max_age_s=0.2 (JSON values)")
    return parser


def plain(text: str) -> str:
    """Docstring text for a terminal: ``literal`` → literal."""
    return text.replace("``", "")


def overrides_from(args: argparse.Namespace) -> dict[str, Any]:
    """The settings that flags override, as a nested dict."""
    out: dict[str, Any] = {}
    for item in args.set:
        path, sep, raw = item.partition("=")
        if not sep or not path:
            raise ConfigError(f"--set {item!r}: expected FIELD=VALUE")
        *parents, leaf = path.split(".")
        target = out
        for p in parents:
            target = target.setdefault(p, {})
        try:
            target[leaf] = json.loads(raw)
        except json.JSONDecodeError:
            target[leaf] = raw
    if args.instance:
        out["instance"] = args.instance
    if args.log_level:
        out["log_level"] = args.log_level
    if args.connect:
        out.setdefault("bus", {}).setdefault("zenoh", {})["connect"] = args.connect
    return out


def service_main(name: str, settings_cls: type[S], body: Callable[[Node], None],
                 argv: Sequence[str] | None = None, description: str = "",
                 flags: Callable[[argparse.ArgumentParser], None] | None = None,
                 flag_overrides: Callable[[argparse.Namespace], dict[str, Any]] | None = None,
                 ) -> int:
    """Parse flags, load and validate settings, then run the service until stopped.

    ``flags`` adds service-specific flags; ``flag_overrides`` turns them into settings.
    """
    parser = base_parser(f"stb {name}", description)
    if flags:
        flags(parser)
    args = parser.parse_args(argv)
    try:
        overrides = overrides_from(args)
        if flag_overrides:
            overrides.update(flag_overrides(args))
        settings = load_settings(settings_cls, args.lab, overrides)
    except ConfigError as err:
        print(f"stb {name}: {err}", file=sys.stderr)
        return EXIT_CONFIG
    configure_logging(settings.log_level)
    return run_node(name, settings, body)


# --- tools (monitor, record, replay): bus clients without a liveliness token of their own -------


class ToolError(Exception):
    """Ends a tool: ``tool_main`` prints the message and returns the exit code."""

    def __init__(self, message: str, code: int = EXIT_CONFIG) -> None:
        super().__init__(message)
        self.code = code


def tool_main(name: str, body: Callable[[], int]) -> int:
    """Run a tool's body; a ToolError becomes ``stb NAME: message`` and its exit code."""
    try:
        return body()
    except ToolError as err:
        print(f"stb {name}: {err}", file=sys.stderr)
        return err.code


def tool_settings(settings_cls: type[S], args: argparse.Namespace) -> S:
    """The tool's settings from ``--lab`` and the common flags; logging configured."""
    try:
        settings = load_settings(settings_cls, args.lab, overrides_from(args))
    except ConfigError as err:
        raise ToolError(str(err)) from err
    configure_logging(settings.log_level)
    return settings


def tool_session(settings: ServiceSettings) -> zenoh.Session:
    try:
        return open_session(settings.zenoh_settings())
    except BusUnreachable as err:
        raise ToolError(str(err), EXIT_UNREACHABLE) from err


def checked_key_exprs(exprs: Sequence[str]) -> list[str]:
    """The key expressions if Zenoh accepts every one, else a ToolError naming the bad one."""
    for expr in exprs:
        try:
            zenoh.KeyExpr(expr)
        except zenoh.ZError as err:
            raise ToolError(f"bad key expression {expr!r}: {err}") from err
    return list(exprs)
