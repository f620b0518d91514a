"""A camera on this host through OpenCV (device number or stream URL), read on a thread of
its own: each frame as a gray image with the time it was grabbed. The gantry uses it for
``frames = "opencv:…"``; ``stb camera`` puts its frames on the bus."""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import cv2

log = logging.getLogger(__name__)
Frame = tuple[float, np.ndarray]  # (capture time, gray uint8 image)


def parse_source(source: str) -> int | str:
    """``0`` → device 0; anything else (a URL, a file) as it is."""
    return int(source) if source.isdigit() else source


V4L2_MANUAL_EXPOSURE = 1  # V4L2_EXPOSURE_MANUAL of the exposure_auto menu (3: aperture priority)
V4L2_EXPOSURE_UNIT_MS = 0.1  # V4L2_CID_EXPOSURE_ABSOLUTE counts 100 µs


def set_exposure(camera: cv2.VideoCapture, exposure_ms: float, source: str) -> str:
    """Auto exposure off and the exposure time set (V4L2's units, which OpenCV's V4L2 backend
    passes through); what the camera says it took, for the log. A camera or stream that does
    not take it keeps its own, and the answer says so."""
    import cv2

    backend = camera.getBackendName() if hasattr(camera, "getBackendName") else "?"
    manual = camera.set(cv2.CAP_PROP_AUTO_EXPOSURE, V4L2_MANUAL_EXPOSURE)
    taken = camera.set(cv2.CAP_PROP_EXPOSURE, exposure_ms / V4L2_EXPOSURE_UNIT_MS)
    if not (manual and taken):
        return (f"camera {source} ({backend}) did not take exposure_ms {exposure_ms:g}: it "
                "keeps its own (a stream's or a file's is set on the camera itself)")
    got = camera.get(cv2.CAP_PROP_EXPOSURE) * V4L2_EXPOSURE_UNIT_MS
    return f"camera {source} ({backend}): exposure {got:g} ms (asked {exposure_ms:g})"


def capture(source: str, stop: threading.Event, deliver: Callable[[Frame], None],
            retry_s: float = 2.0, exposure_ms: float | None = None) -> None:
    """Read ``source`` until ``stop``, handing each frame to ``deliver``; reopen it (every
    ``retry_s``) when it fails. The capture time is taken when the frame is grabbed, before
    it is decoded. ``exposure_ms``: set each time the camera is opened (None: its own)."""
    import cv2  # here: a gantry that takes its frames from the bus does without OpenCV

    device = parse_source(source)
    camera = None
    while not stop.is_set():
        if camera is None or not camera.isOpened():
            camera = cv2.VideoCapture(device)
            if not camera.isOpened():
                log.warning("camera %s cannot be opened; retrying", source)
                stop.wait(retry_s)
                continue
            if exposure_ms is not None:
                said = set_exposure(camera, exposure_ms, source)
                (log.warning if "did not take" in said else log.info)("%s", said)
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
