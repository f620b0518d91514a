"""The crater's height map as the page draws it: a colour PNG and its extent and scale."""

from __future__ import annotations

import json
import logging
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from common.heightmap import HeightMap

log = logging.getLogger(__name__)
DEFAULT_EXTENT_MM = (-3000.0, 3000.0, -3000.0, 3000.0)
COLOURS = "terrain"  # matplotlib's; it loads when the map is first drawn, not at start-up
SCALE_STEPS = 11  # colours the page's scale is drawn from, lowest to highest


def map_png(height_map: HeightMap) -> bytes:
    """The height map as a colour PNG, row 0 at the top = the largest y (north up)."""
    import cv2  # with matplotlib, when the map is first drawn: not in every page's start-up
    from matplotlib import colormaps

    h = height_map.heights_mm.astype(float)
    span = float(h.max() - h.min()) or 1.0
    rgba = colormaps[COLOURS]((h - h.min()) / span)
    bgr = (rgba[::-1, :, 2::-1] * 255).astype(np.uint8)
    ok, png = cv2.imencode(".png", np.ascontiguousarray(bgr))
    if not ok:
        raise ValueError("height map does not encode as PNG")
    return png.tobytes()


def map_info(height_map: HeightMap) -> dict[str, Any]:
    """The map's extent and its colour scale: the lowest and highest height and the colours
    between them, as the PNG shows them."""
    from matplotlib import colormaps

    h = height_map.heights_mm
    steps = colormaps[COLOURS](np.linspace(0.0, 1.0, SCALE_STEPS))
    return {"extent_mm": list(height_map.extent_mm), "image": True,
            "height_mm": [round(float(h.min()), 1), round(float(h.max()), 1)],
            "colours": ["#{:02x}{:02x}{:02x}".format(*(int(round(c * 255)) for c in rgba[:3]))
                        for rgba in steps]}


class CraterImage:
    """The height map as the page gets it, read when first asked for and again (at most every
    ``retry_s``) while the file is missing: the sim may write it after the page started."""

    def __init__(self, path: Path | None, retry_s: float = 2.0) -> None:
        self.path, self.retry_s = path, retry_s
        self._lock = threading.Lock()
        self._tried_at = -float("inf")
        self.info = json.dumps({"extent_mm": DEFAULT_EXTENT_MM, "image": False})
        self.png: bytes | None = None

    def get(self) -> tuple[str, bytes | None]:
        with self._lock:
            if self.png is None and self.path is not None and (
                    time.monotonic() - self._tried_at >= self.retry_s):
                self._tried_at = time.monotonic()
                self._load(self.path)
            return self.info, self.png

    def waiting_for(self) -> str:
        """Why the page shows no crater yet: its file is not there (yet); "" otherwise."""
        if self.png is None and self.path is not None and not self.path.exists():
            return (f"waiting for the crater height map {self.path} (the sim writes it as it "
                    "starts; a real lab's comes from stb crater import)")
        return ""

    def _load(self, path: Path) -> None:
        if not path.exists():
            return
        try:
            height_map = HeightMap.load(path)
            self.png = map_png(height_map)
        except ValueError as err:
            log.error("height map not shown: %s", err)
            self.path = None  # a broken file stays broken: do not read it every request
            return
        self.info = json.dumps(map_info(height_map))
        log.info("height map %s shown", path)
