"""A camera on this host through OpenCV (device number or stream URL), read on a thread of
its own: each frame as a gray image with the time it was grabbed. The gantry uses it for
``frames = "opencv:…"``; ``stb camera`` puts its frames on the bus."""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable

import cv2
import numpy as np

log = logging.getLogger(__name__)
Frame = tuple[float, np.ndarray]  # (capture time, gray uint8 image)


def parse_source(source: str) -> int | str:
    """``0`` → device 0; anything else (a URL, a file) as it is."""
    return int(source) if source.isdigit() else source


def capture(source: str, stop: threading.Event, deliver: Callable[[Frame], None],
            retry_s: float = 2.0) -> None:
    """Read ``source`` until ``stop``, handing each frame to ``deliver``; reopen it (every
    ``retry_s``) when it fails. The capture time is taken when the frame is grabbed, before
    it is decoded."""
    device = parse_source(source)
    camera = None
    while not stop.is_set():
        if camera is None or not camera.isOpened():
            camera = cv2.VideoCapture(device)
            if not camera.isOpened():
                log.warning("camera %s cannot be opened; retrying", source)
                stop.wait(retry_s)
                continue
        if not camera.grab():
            camera.release()
            camera = None
            continue
        grabbed = time.time()
        ok, image = camera.retrieve()
        if not ok:
            continue
        if image.ndim == 3:
            image = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
        deliver((grabbed, image))
    if camera is not None:
        camera.release()
