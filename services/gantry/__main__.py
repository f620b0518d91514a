"""``stb gantry``: the crane follows the robot (paper §3). The paper's experiments on a
simulated clock: ``stb experiment gantry --help``."""

from __future__ import annotations

import sys
from collections.abc import Sequence

from services.entry import service_main
from services.gantry.settings import GantrySettings


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    from services.gantry.service import run

    return service_main("gantry", GantrySettings, run, argv, __doc__ or "")


if __name__ == "__main__":
    sys.exit(main())
