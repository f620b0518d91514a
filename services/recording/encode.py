"""A camera's frames as H.264 for Foxglove's ``CompressedVideo`` (libx264 through PyAV, a
binding of FFmpeg).

Foxglove plays H.264 given as an Annex B byte stream, one access unit per message, without
B-frames, with the SPS and PPS before each keyframe: the encoder runs x264's ``ultrafast``
preset tuned for ``zerolatency`` (no B-frames, no look-ahead: every frame comes out as it
goes in, so each message carries its own frame's capture time), a keyframe at least every
``keyframe_every`` frames (a player can start there; ``repeat-headers`` puts SPS and PPS
before each). Its quality is x264's constant rate factor ``crf`` (23 is x264's default, a
higher one is smaller). A frame of another size starts a new stream (with a keyframe).
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction

import av
import numpy as np

FORMAT = "h264"  # CompressedVideo.format


@dataclass(frozen=True)
class EncodedFrame:
    data: bytes  # one access unit, Annex B
    time_s: float  # its frame's capture time
    keyframe: bool


class H264Stream:
    def __init__(self, keyframe_every: int = 30, crf: int = 28) -> None:
        self.keyframe_every, self.crf = keyframe_every, crf
        self._context: av.VideoCodecContext | None = None
        self._size: tuple[int, int] | None = None
        self._count = 0
        self._times: dict[int, float] = {}

    def encode(self, image: np.ndarray, time_s: float) -> list[EncodedFrame]:
        """``image``: grey (H×W) or BGR (H×W×3) uint8; the access units it completes (one,
        with ``zerolatency``). Odd sizes lose their last row or column (4:2:0 needs even)."""
        height, width = image.shape[0] & ~1, image.shape[1] & ~1
        image = np.ascontiguousarray(image[:height, :width])
        if self._size != (width, height):
            self._open(width, height)
        assert self._context is not None
        frame = av.VideoFrame.from_ndarray(image, format="gray" if image.ndim == 2 else "bgr24")
        frame = frame.reformat(format="yuv420p")
        frame.pts = self._count
        self._times[self._count] = time_s
        self._count += 1
        return self._packets(self._context.encode(frame))

    def _open(self, width: int, height: int) -> None:
        context = av.CodecContext.create("libx264", "w")
        assert isinstance(context, av.VideoCodecContext)
        context.width, context.height, context.pix_fmt = width, height, "yuv420p"
        context.time_base = Fraction(1, 1000)
        context.gop_size = self.keyframe_every
        context.max_b_frames = 0
        context.options = {"preset": "ultrafast", "tune": "zerolatency", "crf": str(self.crf),
                           "x264-params": f"repeat-headers=1:keyint={self.keyframe_every}"}
        context.open()
        self._context, self._size = context, (width, height)
        self._count, self._times = 0, {}

    def _packets(self, packets: list[av.Packet]) -> list[EncodedFrame]:
        out = []
        for packet in packets:
            time_s = self._times.pop(packet.pts, None) if packet.pts is not None else None
            if time_s is not None:
                out.append(EncodedFrame(bytes(packet), time_s, bool(packet.is_keyframe)))
        return out
