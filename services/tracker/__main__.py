"""``stb tracker``: Qualisys mocap in; markers and the robot's position out."""

from __future__ import annotations

import sys
from collections.abc import Sequence

from services.args import service_args


def main(argv: Sequence[str] | None = None) -> int:
    args = service_args("tracker", __doc__ or "", argv)
    from services.entry import run_service
    from services.tracker.service import run
    from services.tracker.settings import TrackerSettings

    return run_service("tracker", TrackerSettings, run, args)


if __name__ == "__main__":
    sys.exit(main())
