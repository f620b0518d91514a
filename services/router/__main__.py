"""``stb router``: an embedded Zenoh router, e.g. ``stb router --listen tcp/0.0.0.0:7447``."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from services.args import service_args

if TYPE_CHECKING:
    from common.node import Node


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
    args = service_args("router", __doc__ or "", argv, flags=_flags)
    from services.entry import run_service
    from services.router.settings import RouterSettings

    return run_service("router", RouterSettings, _wait, args, flag_overrides=_overrides)


if __name__ == "__main__":
    sys.exit(main())
