"""``stb router``: an embedded Zenoh router, e.g. ``stb router --listen tcp/0.0.0.0:7447``."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from common.node import Node
from services.entry import service_main
from services.router.settings import RouterSettings


def _wait(node: Node) -> None:
    node.stop.wait()


def _flags(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--listen", action="append", metavar="ENDPOINT",
                        help="endpoint to listen on (repeatable); default tcp/127.0.0.1:7447")
    parser.add_argument("--config", type=Path, metavar="ZENOH_CONFIG",
                        help="Zenoh JSON5/YAML router config, e.g. deploy/zenoh/router.json5")


def _overrides(args: argparse.Namespace) -> dict[str, Any]:
    out: dict[str, Any] = {}
    if args.listen:
        out["listen"] = args.listen
    if args.config:
        out["config_file"] = args.config.resolve()
    return out


def main(argv: Sequence[str] | None = None) -> int:
    return service_main("router", RouterSettings, _wait, argv, __doc__ or "",
                        flags=_flags, flag_overrides=_overrides)


if __name__ == "__main__":
    sys.exit(main())
