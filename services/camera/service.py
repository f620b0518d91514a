"""Camera service: the tracking camera's frames on the bus (the gantry reads them).

Reads:      a camera on this host through OpenCV (device number or stream URL)
Publishes:  stb/gantry/camera/frame (CameraFrame: mono8 or JPEG), each stamped with the time
            it was grabbed, at most max_rate_hz; reopens the camera when it fails
"""

from __future__ import annotations

import itertools
import logging
import threading
import time

import cv2

from common import keys
from common import messages as m
from common.capture import Frame, capture
from common.node import Node, run_every
from services.camera.settings import CameraSettings

log = logging.getLogger(__name__)


def run(node: Node[CameraSettings]) -> None:
    s = node.settings
    publisher = FramePublisher(node, s)
    reader = threading.Thread(target=capture, args=(s.source, node.stop, publisher.publish),
                              kwargs={"exposure_ms": s.exposure_ms}, name="camera", daemon=True)
    reader.start()
    log.info("camera %s: frames from %s on %s", s.name, s.source,
             keys.GANTRY_FRAME.key(node.bus.prefix))
    run_every(1.0, node.stop, publisher.check, "camera status")
    reader.join(timeout=5)


class FramePublisher:
    def __init__(self, node: Node, s: CameraSettings) -> None:
        self.node, self.s = node, s
        self.seq = itertools.count()
        self.last_s = 0.0  # the last frame sent
        self.started_s = time.time()

    def check(self) -> None:
        """Health: degraded while no frame has come for two seconds."""
        quiet = time.time() - max(self.last_s, self.started_s)
        if quiet > 2.0:
            self.node.set_status("degraded", f"no frames from {self.s.source} for "
                                 f"{quiet:.0f} s")
        else:
            self.node.set_status("ok")

    def publish(self, frame: Frame) -> None:
        grabbed, image = frame
        if grabbed - self.last_s < 1 / self.s.max_rate_hz:
            return
        self.last_s = grabbed
        if self.s.encoding == "jpeg":
            ok, jpeg = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY,
                                                    self.s.jpeg_quality])
            if not ok:
                log.warning("frame does not encode as JPEG: dropped")
                return
            data = jpeg.tobytes()
        else:
            data = image.tobytes()
        height, width = image.shape
        self.node.bus.publish(keys.GANTRY_FRAME, m.CameraFrame(
            measured_s=grabbed, camera=self.s.name, seq=next(self.seq), width_px=width,
            height_px=height, encoding=self.s.encoding, data=data))
