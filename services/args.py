"""The command line every ``stb`` command shares, without importing anything heavy: a command
parses its flags (and answers ``--help``) before it imports Zenoh, pydantic, numpy or OpenCV.

``--lab FILE``, ``--instance``, ``--connect``, ``--log-level``, ``--set k=v``.
"""

from __future__ import annotations

import argparse
import re
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from common.errors import ConfigError
from common.setting_text import setting_value

EXIT_CONFIG = 2
EXIT_DISK = 5
"""The disk is (nearly) full: what was being written stopped, its file readable."""
EXIT_INTERRUPTED = 130
"""Interrupted (SIGINT) before the command began to handle it: nothing was done."""
NUMBERS = re.compile(r"^-\.?\d[\d.,eE+-]*$")
"""A value that starts with a minus: -5, -.5, -1e3, -100,200,3000 (a vector)."""


class Parser(argparse.ArgumentParser):
    """argparse, but a value that starts with a minus and is a number or a comma-separated
    vector of them is a value, never an option: ``--initial -100,200,3000,180,0,180`` and
    ``--target -1200,300,0`` work as written (plain argparse takes only a lone number so)."""

    def _parse_optional(self, arg_string: str) -> tuple | None:
        if NUMBERS.match(arg_string):
            return None
        return super()._parse_optional(arg_string)


def base_parser(prog: str, description: str) -> argparse.ArgumentParser:
    """A command's parser with the common flags; ``description`` (a module docstring) is
    shown as written, its RST literals as plain text."""
    parser = Parser(prog=prog, description=plain(description),
                    formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--lab", type=Path, metavar="FILE",
                        help="lab config file (TOML); default: $STB_LAB, else built-in defaults")
    parser.add_argument("--instance", help="instance name (default: from config, else 'main')")
    parser.add_argument("--connect", action="append", metavar="ENDPOINT",
                        help="router endpoint, e.g. tcp/10.0.0.2:7447 (repeatable)")
    parser.add_argument("--log-level", choices=["DEBUG", "INFO", "WARNING", "ERROR"])
    parser.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                        help="override one setting, e.g. --set bus.max_age_s=0.2 (lists and "
                        "tables in JSON)")
    return parser


def service_args(name: str, description: str, argv: Sequence[str] | None = None,
                 flags: Callable[[argparse.ArgumentParser], None] | None = None
                 ) -> argparse.Namespace:
    """A service's flags parsed (``--help`` answered and the process ended here)."""
    parser = base_parser(f"stb {name}", description)
    if flags:
        flags(parser)
    return parser.parse_args(argv)


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
        target[leaf] = setting_value(raw)  # read as the environment's values are
    if args.instance:
        out["instance"] = args.instance
    if args.log_level:
        out["log_level"] = args.log_level
    if args.connect:
        out.setdefault("bus", {}).setdefault("zenoh", {})["connect"] = args.connect
    return out
