"""``stb ptz [--instance ptz1]``: one AXIS camera follows the robot.
``stb ptz aim --pose POSE.json --target X,Y,Z [--mount standing|hanging] [--json]``: eq. 4."""

from __future__ import annotations

import sys
from collections.abc import Sequence

from services.entry import service_main
from services.ptz.service import run
from services.ptz.settings import PtzSettings


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["aim"]:
        from services.ptz.aim_cli import main as aim_main

        return aim_main(argv[1:])
    return service_main("ptz", PtzSettings, run, argv, __doc__ or "")


if __name__ == "__main__":
    sys.exit(main())
