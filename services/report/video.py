"""The recording's camera videos for the report: Foxglove's ``CompressedVideo`` channels
(H.264, Annex B, as ``stb record`` writes them) read back by their own protobuf schema and
decoded with PyAV — a still at a moment, or the frames of a stretch of the run.

A still is found without decoding the whole run: the file's chunk index gives the messages of
a window before the moment (``iter_messages(starting_at=…)``), decoding starts at the last
keyframe in it (an IDR picture; ``stb record`` writes one at least every 30 frames, with its
SPS and PPS) and ends at the last frame taken at or before the moment.
"""

from __future__ import annotations

import logging
from collections import deque
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import av
import numpy as np
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from google.protobuf.message import DecodeError

from common.mcap_file import messages_of, topics_of

log = logging.getLogger(__name__)
VIDEO_SCHEMA = "foxglove.CompressedVideo"
LOOKBACK_S = 15.0  # a keyframe lies this close before any moment (30 frames at 2 fps and up)
_CLASSES: dict[tuple[str, bytes], Any] = {}


def message_class(name: str, descriptors: bytes) -> Any:
    """The protobuf class of ``name`` from a serialized FileDescriptorSet (a typed channel's
    schema data)."""
    cls = _CLASSES.get((name, descriptors))
    if cls is None:
        pool = descriptor_pool.DescriptorPool()
        for file in descriptor_pb2.FileDescriptorSet.FromString(descriptors).file:
            pool.Add(file)
        cls = _CLASSES[(name, descriptors)] = message_factory.GetMessageClass(
            pool.FindMessageTypeByName(name))
    return cls


@dataclass(frozen=True)
class Unit:
    """One access unit of a video channel: its frame's capture time and its bytes."""

    time_s: float
    data: bytes

    @property
    def keyframe(self) -> bool:
        return is_keyframe(self.data)


def is_keyframe(annex_b: bytes) -> bool:
    """Whether an access unit holds an IDR picture (NAL unit type 5), where decoding can
    start."""
    start = 0
    while (found := annex_b.find(b"\x00\x00\x01", start)) >= 0 and found + 3 < len(annex_b):
        if annex_b[found + 3] & 0x1F == 5:
            return True
        start = found + 3
    return False


def video_topics(paths: Sequence[Path]) -> list[str]:
    """The recording's video channels (``/observation/video``, ``/gantry/image``, …)."""
    return sorted({topic for path in paths for topic, schema in topics_of(path).items()
                   if schema == VIDEO_SCHEMA})


def units(paths: Sequence[Path], topic: str, start_s: float | None = None,
          end_s: float | None = None) -> Iterator[Unit]:
    """The channel's access units between two times (None: from the start, to the end), in
    order, file after file (an unfinished file up to where it breaks off)."""
    start = None if start_s is None else max(0, int(start_s * 1e9))
    end = None if end_s is None else int(end_s * 1e9)
    for path in paths:
        for schema, _, message in messages_of(path, [topic], start, end):
            if schema is None or schema.name != VIDEO_SCHEMA:
                continue
            try:
                video = message_class(schema.name, schema.data).FromString(message.data)
            except (KeyError, TypeError, DecodeError) as err:  # not Foxglove's schema
                log.warning("%s in %s: not a CompressedVideo (%s); left out", topic,
                            path, err)
                return
            if video.format == "h264":
                yield Unit(message.log_time / 1e9, bytes(video.data))


def decoded(stream: Iterator[Unit]) -> Iterator[tuple[float, np.ndarray]]:
    """(capture time, BGR picture) of each unit, decoded from the first keyframe on."""
    decoder, started = av.CodecContext.create("h264", "r"), False
    for unit in stream:
        started = started or unit.keyframe
        if not started:
            continue
        try:
            frames = decoder.decode(av.Packet(unit.data))
        except av.error.FFmpegError:
            continue  # a damaged unit: the next keyframe repairs the picture
        for frame in frames:
            yield unit.time_s, frame.to_ndarray(format="bgr24")


def still(paths: Sequence[Path], topic: str, at_s: float) -> tuple[float, np.ndarray] | None:
    """The channel's picture taken last at or before ``at_s`` (its time and BGR pixels), or
    None when there is none within ``LOOKBACK_S``."""
    window = list(units(paths, topic, at_s - LOOKBACK_S, at_s))
    keyframes = [i for i, unit in enumerate(window) if unit.keyframe]
    if not keyframes:
        return None
    last = deque(decoded(iter(window[keyframes[-1]:])), maxlen=1)
    return last.pop() if last else None
