"""Running a service or a tool from its parsed command line (the flags themselves, light to
import, are in ``services.args``): settings loaded and checked, logging, the node, errors."""

from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Callable, Sequence
from typing import Any, TypeVar

import zenoh

from common.bus import BusUnreachable, open_session
from common.errors import ConfigError
from common.node import EXIT_UNREACHABLE, Node, configure_logging, run_node
from common.settings import ServiceSettings, load_settings
from services.args import EXIT_CONFIG, overrides_from

S = TypeVar("S", bound=ServiceSettings)

log = logging.getLogger(__name__)


def run_service(name: str, settings_cls: type[S], body: Callable[[Node], None],
                args: argparse.Namespace,
                flag_overrides: Callable[[argparse.Namespace], dict[str, Any]] | None = None,
                ) -> int:
    """Load and validate settings from parsed flags (``services.args.service_args``), then
    run the service until stopped. ``flag_overrides`` turns its own flags into settings."""
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
