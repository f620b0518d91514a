"""``stb camera``: the tracking camera's frames on the bus (stb/gantry/camera/frame), from a
camera on this host through OpenCV ([camera] source: a device number or a stream URL)."""

from __future__ import annotations

import sys
from collections.abc import Sequence

from services.args import service_args


def main(argv: Sequence[str] | None = None) -> int:
    args = service_args("camera", __doc__ or "", argv)
    from services.camera.service import run
    from services.camera.settings import CameraSettings
    from services.entry import run_service

    return run_service("camera", CameraSettings, run, args)


if __name__ == "__main__":
    sys.exit(main())
