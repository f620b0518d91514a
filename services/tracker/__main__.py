"""``stb tracker``: Qualisys mocap in; markers and the robot's position out."""

from __future__ import annotations

import sys
from collections.abc import Sequence

from services.entry import service_main
from services.tracker.service import run
from services.tracker.settings import TrackerSettings


def main(argv: Sequence[str] | None = None) -> int:
    return service_main("tracker", TrackerSettings, run, argv, __doc__ or "")


if __name__ == "__main__":
    sys.exit(main())
