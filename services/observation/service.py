"""Observation service: the crane's observation camera's video on the bus.

Reads:      the camera's MJPEG stream (VAPIX mjpg/video.cgi at fps, Digest/Basic/no auth);
            reconnects after a failure, waiting 1 s doubling to 10 s
Publishes:  stb/video/<name> (CameraFrame: the camera's JPEGs as they came, colour), each
            stamped when it arrived — the clock every recorded sample is on
Health:     degraded while no frame has come for two frames' time (2 s at least), naming why
"""

from __future__ import annotations

import itertools
import logging
import time

from common import keys
from common import messages as m
from common.jpeg import jpeg_size
from common.mjpeg import CameraVideo
from common.node import Node, run_every
from services.observation.settings import ObservationSettings

log = logging.getLogger(__name__)


def run(node: Node[ObservationSettings]) -> None:
    s = node.settings
    publisher = VideoPublisher(node, s)
    video = CameraVideo(s.name, s.connection(), s.fps, s.resolution, publisher.publish).start()
    publisher.video = video
    log.info("observation camera %s: video from %s on %s", s.name, s.url,
             keys.VIDEO.key(node.bus.prefix, camera=s.name))
    try:
        run_every(1.0, node.stop, publisher.check, "observation status")
    finally:
        video.stop()


class VideoPublisher:
    """The camera's JPEGs onto the bus as they came (not decoded); its health."""

    def __init__(self, node: Node[ObservationSettings], s: ObservationSettings) -> None:
        self.node, self.s = node, s
        self.seq = itertools.count(1)
        self.last_s = time.time()  # the last frame sent (or the start)
        self.quiet_limit_s = max(2.0, 2.0 / s.fps)
        self.video: CameraVideo | None = None
        self.dropped = 0

    def publish(self, camera: str, jpeg: bytes, received_s: float) -> None:
        size = jpeg_size(jpeg)
        if size is None or 0 in size:
            self.dropped += 1
            if self.dropped == 1:
                log.warning("camera %s sent a part that is not a JPEG: dropped (and counted)",
                            camera)
            return
        self.last_s = received_s
        self.node.bus.publish(keys.VIDEO, m.CameraFrame(
            measured_s=received_s, camera=camera, seq=next(self.seq), width_px=size[0],
            height_px=size[1], encoding="jpeg", data=jpeg), camera=camera)

    def check(self) -> None:
        quiet = time.time() - self.last_s
        if quiet <= self.quiet_limit_s:
            self.node.set_status("ok")
            return
        why = self.video.problem if self.video is not None and self.video.problem else \
            "the stream is open but sends nothing"
        self.node.set_status("degraded", f"no picture from {self.s.url} for {quiet:.0f} s: "
                             f"{why}")
