"""``stb sim [--scenario locomotive|walker|calibration|parked] [--seed N]``: the simulated lab.
``stb sim estop [--release]``: press or release the simulated crane's e-stop.
``stb sim scan --out FILE``: the crater as a laser scanner would deliver it (.ply, .xyz)."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from typing import Any

from services.args import service_args
from services.sim.scenarios import SCENARIOS


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
    if argv[:1] == ["scan"]:
        from services.sim.scan_cli import main as scan_main

        return scan_main(argv[1:])
    args = service_args("sim", __doc__ or "", argv, flags=_flags)
    from services.entry import run_service
    from services.sim.service import run
    from services.sim.settings import SimSettings

    return run_service("sim", SimSettings, run, args, flag_overrides=_overrides)


if __name__ == "__main__":
    sys.exit(main())
