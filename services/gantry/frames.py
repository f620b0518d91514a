"""Tracking-camera frames: from the bus (the camera host publishes them — the sim in local
runs) or from a camera on this host through OpenCV. Either way ``take()`` gives the newest
frame not taken yet, with its capture time, or None; ``take_recent()`` the frames that came
since the last take, newest first (the gantry looks at the older ones when the newest does not
show the robot: a stray or spoofed frame then does not blind it)."""

from __future__ import annotations

import logging
import threading
from collections import deque
from collections.abc import Sequence
from typing import Protocol

import numpy as np

from common import messages as m
from common.capture import Frame, capture
from common.jpeg import JpegError, decode_gray

log = logging.getLogger(__name__)


class FrameSource(Protocol):
    """Where the tracking camera's frames come from: the bus, a camera on this host, or the
    sim's camera in the experiments."""

    def take(self) -> Frame | None:
        """The newest frame not taken yet, or None."""

    def take_recent(self) -> Sequence[Frame]:
        """The frames not taken yet, newest first (a source may keep only the newest)."""


class FrameInbox:
    """The last ``keep`` frames, handed over once."""

    def __init__(self, keep: int = 8) -> None:
        self.keep = keep
        self._lock = threading.Lock()
        self._frames: deque[Frame] = deque(maxlen=keep)

    def put(self, frame: Frame) -> None:
        with self._lock:
            self._frames.append(frame)

    def put_message(self, msg: m.CameraFrame) -> None:
        """A frame from the bus; one that does not decode is logged and left out."""
        frame = decode(msg)
        if frame is not None:
            self.put(frame)

    def take(self) -> Frame | None:
        recent = self.take_recent()
        return recent[0] if recent else None

    def take_recent(self) -> list[Frame]:
        with self._lock:
            frames = list(reversed(self._frames))
            self._frames.clear()
        return frames


def decode(msg: m.CameraFrame) -> Frame | None:
    """A bus frame as an image; None (logged) if its bytes do not match its header."""
    if msg.encoding == "mono8":
        if len(msg.data) != msg.width_px * msg.height_px:
            log.warning("frame %d: %d bytes for %d×%d mono8", msg.seq, len(msg.data),
                        msg.width_px, msg.height_px)
            return None
        image = np.frombuffer(msg.data, np.uint8).reshape(msg.height_px, msg.width_px)
    else:
        try:
            image = decode_gray(msg.data, (msg.width_px, msg.height_px))
        except JpegError as err:
            log.warning("frame %d: %s", msg.seq, err)
            return None
    return msg.measured_s, image


class OpenCvFrames(FrameInbox):
    """A camera on this host (device number or stream URL), read on a thread of its own."""

    def __init__(self, source: str, stop: threading.Event) -> None:
        super().__init__()
        self.source = source
        threading.Thread(target=capture, args=(source, stop, self.put), name="camera",
                         daemon=True).start()
