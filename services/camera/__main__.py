"""``stb camera``: the tracking camera's frames on the bus (stb/gantry/camera/frame), from a
camera on this host through OpenCV ([camera] source: a device number or a stream URL)."""

from __future__ import annotations

import sys
from collections.abc import Sequence

from services.camera.settings import CameraSettings
from services.entry import service_main


def main(argv: Sequence[str] | None = None) -> int:
    from services.camera.service import run

    return service_main("camera", CameraSettings, run, argv, __doc__ or "")


if __name__ == "__main__":
    sys.exit(main())
