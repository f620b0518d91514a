"""``stb observation``: the crane's observation camera (paper §3.1: the colour camera beside the
tracking camera, "for data acquisition and monitoring") on the bus — its MJPEG stream (an IP
camera's VAPIX ``mjpg/video.cgi``, [observation] url) as JPEGs on stb/video/observation, which
the page shows and ``stb record`` keeps as H.264 video."""

from __future__ import annotations

import sys
from collections.abc import Sequence

from services.args import service_args


def main(argv: Sequence[str] | None = None) -> int:
    args = service_args("observation", __doc__ or "", argv)
    from services.entry import run_service
    from services.observation.service import run
    from services.observation.settings import ObservationSettings

    return run_service("observation", ObservationSettings, run, args)


if __name__ == "__main__":
    sys.exit(main())
