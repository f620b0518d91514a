"""The JSON copy of a recorded sample, so that Foxglove (which cannot decode msgpack) shows it.

Messages become their fields as JSON (bytes as base64); camera images become
``foxglove.CompressedImage`` (JPEG as sent; raw mono8 tracking-camera frames are JPEG-encoded
for the copy only — the msgpack channel keeps the exact frame).
"""

from __future__ import annotations

import base64
import json

import cv2
import numpy as np

from common import codec
from common import messages as m

COMPRESSED_IMAGE = ("foxglove.CompressedImage", {
    "title": "foxglove.CompressedImage", "type": "object",
    "properties": {
        "timestamp": {"type": "object", "properties": {"sec": {"type": "integer", "minimum": 0},
                                                       "nsec": {"type": "integer", "minimum": 0}}},
        "frame_id": {"type": "string"},
        "data": {"type": "string", "contentEncoding": "base64"},
        "format": {"type": "string"}}})
JPEG_QUALITY = 80


def json_copy(msg: m.Message | dict) -> tuple[bytes, tuple[str, dict] | None]:
    """(JSON bytes, schema or None for schemaless JSON) of a decoded sample."""
    image = _image(msg)
    if image is not None:
        return image, COMPRESSED_IMAGE
    return json.dumps(codec.to_plain(msg), allow_nan=False).encode(), None


def _image(msg: m.Message | dict) -> bytes | None:
    if isinstance(msg, m.PtzPreview):
        jpeg, frame_id = msg.jpeg, msg.camera
    elif isinstance(msg, m.CameraFrame) and msg.encoding == "jpeg":
        jpeg, frame_id = msg.data, msg.camera
    elif isinstance(msg, m.CameraFrame):
        pixels = np.frombuffer(msg.data, np.uint8)
        if pixels.size != msg.width_px * msg.height_px:
            return None
        ok, encoded = cv2.imencode(".jpg", pixels.reshape(msg.height_px, msg.width_px),
                                   [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
        if not ok:
            return None
        jpeg, frame_id = encoded.tobytes(), msg.camera
    else:
        return None
    sec, nsec = divmod(round(msg.measured_s * 1e9), 1_000_000_000)
    return json.dumps({"timestamp": {"sec": sec, "nsec": nsec}, "frame_id": frame_id,
                       "data": base64.b64encode(jpeg).decode("ascii"),
                       "format": "jpeg"}).encode()
