"""``stb sim [--scenario locomotive|walker|calibration|parked] [--seed N]``: the simulated lab.
``stb sim estop [--release]``: press or release the simulated crane's e-stop."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from typing import Any

from services.entry import service_main
from services.sim.robots import SCENARIOS
from services.sim.service import run
from services.sim.settings import SimSettings


def _flags(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--scenario", choices=SCENARIOS)
    parser.add_argument("--seed", type=int)


def _overrides(args: argparse.Namespace) -> dict[str, Any]:
    return {k: v for k, v in (("scenario", args.scenario), ("seed", args.seed)) if v is not None}


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["estop"]:
        from services.sim.estop_cli import main as estop_main

        return estop_main(argv[1:])
    return service_main("sim", SimSettings, run, argv, __doc__ or "", flags=_flags,
                        flag_overrides=_overrides)


if __name__ == "__main__":
    sys.exit(main())
