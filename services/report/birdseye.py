"""``stb report --video``: the bird's-eye view of a run as an MP4 (H.264 through PyAV), the
crane's error at each frame written over it — a minute around the largest crane error by
default (``--video-seconds``; 0: the whole run). Frames keep their capture times (the MP4's
time stamps), so a stretch where the camera sent nothing stays as long as it was."""

from __future__ import annotations

from collections.abc import Sequence
from fractions import Fraction
from pathlib import Path

import av
import cv2
import numpy as np

from services.report.video import decoded, units

BIRDSEYE = "/observation/video"
MATCH_S = 0.5  # the crane's error is shown when one was measured this close to the frame
WARN_MM = 100.0  # the overlay turns red above this error


def error_at(t_error: np.ndarray, error_mm: np.ndarray, when_s: float) -> float | None:
    """The crane error measured nearest ``when_s`` (within ``MATCH_S``), or None."""
    if not len(t_error):
        return None
    i = int(np.searchsorted(t_error, when_s))
    nearest = min((j for j in (i - 1, i) if 0 <= j < len(t_error)),
                  key=lambda j: abs(t_error[j] - when_s))
    return float(error_mm[nearest]) if abs(t_error[nearest] - when_s) <= MATCH_S else None


def overlay(image: np.ndarray, seconds: float, error_mm: float | None) -> np.ndarray:
    """The run's time and the crane's error written on the picture (a copy)."""
    out = image.copy()
    text = f"t {seconds:7.1f} s   crane error " + ("-" if error_mm is None
                                                    else f"{error_mm:.0f} mm")
    colour = (60, 60, 255) if error_mm is not None and error_mm > WARN_MM else (255, 255, 255)
    cv2.rectangle(out, (0, 0), (out.shape[1], 26), (0, 0, 0), -1)
    cv2.putText(out, text, (8, 19), cv2.FONT_HERSHEY_SIMPLEX, 0.6, colour, 1, cv2.LINE_AA)
    return out


def export(paths: Sequence[Path], out: Path, t_error: np.ndarray, error_mm: np.ndarray,
           run_start_s: float, start_s: float | None = None, end_s: float | None = None,
           topic: str = BIRDSEYE) -> int:
    """Write the MP4; returns its number of frames (0: no such video, nothing written)."""
    written, container, stream, first, last_pts = 0, None, None, None, -1
    try:
        for when, image in decoded(units(paths, topic, start_s, end_s)):
            height, width = image.shape[0] & ~1, image.shape[1] & ~1
            if container is None:
                container = av.open(str(out), "w")
                stream = container.add_stream("libx264", rate=30)
                stream.width, stream.height, stream.pix_fmt = width, height, "yuv420p"
                stream.time_base = Fraction(1, 1000)
                stream.options = {"preset": "veryfast", "crf": "23"}
                first = when
            assert stream is not None and first is not None
            frame = av.VideoFrame.from_ndarray(
                overlay(image, when - run_start_s, error_at(t_error, error_mm, when))
                [:height, :width], format="bgr24")
            pts = round((when - first) * 1000)
            if pts <= last_pts:
                continue  # two frames with one capture time: the first stays
            frame.pts, frame.time_base, last_pts = pts, Fraction(1, 1000), pts
            container.mux(stream.encode(frame))
            written += 1
        if container is not None and stream is not None:
            container.mux(stream.encode(None))
    finally:
        if container is not None:
            container.close()
    return written
