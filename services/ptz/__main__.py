"""``stb ptz [--instance ptz1]``: one AXIS camera follows the robot.
``stb ptz aim --pose POSE.json --target X,Y,Z [--json]``: eq. 4."""

from __future__ import annotations

import sys
from collections.abc import Sequence

from services.args import service_args


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["aim"]:
        from services.ptz.aim_cli import main as aim_main

        return aim_main(argv[1:])
    args = service_args("ptz", __doc__ or "", argv)
    from common.ptz_settings import PtzSettings
    from services.entry import run_service
    from services.ptz.service import run

    return run_service("ptz", PtzSettings, run, args)


if __name__ == "__main__":
    sys.exit(main())
