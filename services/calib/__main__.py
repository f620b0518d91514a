"""``stb calib``: the calibration service (keeps and publishes camera poses, collects passpoints).
``stb calib solve PASSPOINTS.csv ...``: a pose from a passpoint file (see --help).
``stb calib collect --camera ptz1 [--count 100]``: collect over the bus, solve, publish."""

from __future__ import annotations

import sys
from collections.abc import Sequence

from services.args import service_args


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["solve"]:
        from services.calib.solve_cli import main as solve_main

        return solve_main(argv[1:])
    if argv[:1] == ["collect"]:
        from services.calib.collect_cli import main as collect_main

        return collect_main(argv[1:])
    args = service_args("calib", __doc__ or "", argv)
    from services.calib.service import run
    from services.calib.settings import CalibSettings
    from services.entry import run_service

    return run_service("calib", CalibSettings, run, args)


if __name__ == "__main__":
    sys.exit(main())
