"""Pictures of a run's moments for the report: at the largest crane error and where alarms
began (``data.moments``), a still from every video channel of the recording (the observation
camera's bird's-eye view first, then the PTZ cameras' videos and the tracking camera) and each
PTZ camera's preview, as JPEG files beside the report's plots."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from common import codec, keys
from common import messages as m
from common.files import write_atomically
from common.mcap_file import messages_of, topics_of
from services.report.video import still, video_topics

PREVIEW_WITHIN_S = 2.0  # a PTZ preview taken this long before a moment still shows it
JPEG_QUALITY = 85


@dataclass
class Moment:
    time_s: float
    what: str
    pictures: list[tuple[str, str]] = field(default_factory=list)  # (file name, caption)


def _order(topic: str) -> tuple[int, str]:
    """The bird's-eye view first, the tracking camera last."""
    return (0 if topic.startswith("/observation") else 2 if topic == "/gantry/image" else 1,
            topic)


def write_stills(paths: Sequence[Path], moments: list[tuple[float, str]], out_dir: Path,
                 run_start_s: float, prefix: str = keys.DEFAULT_PREFIX) -> list[Moment]:
    """Each moment with the pictures written for it (``still-N-NAME.jpg`` in ``out_dir``)."""
    topics = sorted(video_topics(paths), key=_order)
    previews = [k for k in _bus_keys(paths) if keys.topic_for(prefix, k) is keys.PTZ_PREVIEW]
    out = []
    for n, (when, what) in enumerate(moments, start=1):
        moment = Moment(when, what)
        for topic in topics:
            found = still(paths, topic, when)
            if found is not None:
                name = topic.strip("/").replace("/", "-")
                _write(out_dir, f"still-{n}-{name}.jpg", found[1], moment,
                       f"{topic} at {found[0] - run_start_s:.1f} s")
        for key in sorted(previews):
            found_preview = _preview(paths, key, when)
            if found_preview is not None:
                image = cv2.imdecode(np.frombuffer(found_preview.jpeg, np.uint8),
                                     cv2.IMREAD_COLOR)
                if image is not None:
                    _write(out_dir, f"still-{n}-{found_preview.camera}-preview.jpg", image,
                           moment, f"{found_preview.camera} preview at "
                           f"{found_preview.measured_s - run_start_s:.1f} s")
        out.append(moment)
    return out


def _write(out_dir: Path, name: str, image: np.ndarray, moment: Moment, caption: str) -> None:
    ok, jpeg = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
    if ok:
        write_atomically(out_dir / name, jpeg.tobytes())
        moment.pictures.append((name, caption))


def _bus_keys(paths: Sequence[Path]) -> set[str]:
    return {topic for path in paths for topic in topics_of(path)}


def _preview(paths: Sequence[Path], key: str, at_s: float) -> m.PtzPreview | None:
    """The camera's last preview taken within ``PREVIEW_WITHIN_S`` before ``at_s``."""
    last = None
    start, end = int((at_s - PREVIEW_WITHIN_S) * 1e9), int(at_s * 1e9)
    for path in paths:
        for _, _, message in messages_of(path, [key], start, end):
            try:
                last = codec.decode(m.PtzPreview, message.data,
                                    max_bytes=keys.PTZ_PREVIEW.max_payload_bytes)
            except codec.DecodeError:
                continue
    return last
