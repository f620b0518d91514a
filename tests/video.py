"""A short video of a bright marker moving to the right on a dark ground (MJPG AVI): what an
OpenCV frame source reads in tests."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np


def marker_video(path: Path, frames: int, size: tuple[int, int], start: tuple[int, int],
                 radius_px: int, step_px: int = 4) -> Path:
    width, height = size
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"MJPG"), 25, size)
    for i in range(frames):
        frame = np.full((height, width, 3), 12, np.uint8)
        cv2.circle(frame, (start[0] + step_px * i, start[1]), radius_px, (255, 255, 255), -1)
        writer.write(frame)
    writer.release()
    return path
