"""Boxes: the one box type (``Box``), and where a robot can be (``Volume``: anything outside —
a reflection, a glitch, a bad sample — is ignored).

Every range of the project is a ``Box``: the tracker's volume (x, y, z), the gantry's workspace
(x, y, less its margin), the sim crane's travel (x, y), a PTZ head's limits (pan, tilt, zoom).
Their settings keep their own named fields; what they contain and where they clamp to is
decided here only."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np


@dataclass(frozen=True)
class Box:
    """An axis-aligned box: per axis its lowest and highest value, in any number of axes."""

    low: tuple[float, ...]
    high: tuple[float, ...]

    def contains(self, point: Sequence[float] | np.ndarray) -> bool:
        """Inside (edges included), with every coordinate finite."""
        return all(math.isfinite(c) and low <= c <= high
                   for c, low, high in zip(point, self.low, self.high, strict=True))

    def clamp(self, point: Sequence[float] | np.ndarray) -> tuple[float, ...]:
        """The nearest point inside (each coordinate held at its axis' range)."""
        return tuple(min(max(c, low), high)
                     for c, low, high in zip(point, self.low, self.high, strict=True))

    def shrunk(self, margin: float) -> Box:
        """The box ``margin`` inside this one on every side."""
        return Box(tuple(low + margin for low in self.low),
                   tuple(high - margin for high in self.high))


@dataclass(frozen=True)
class Volume:
    """Where a robot can be; anything outside (a reflection, a glitch) is ignored."""

    x_min_mm: float = -5000.0
    x_max_mm: float = 5000.0
    y_min_mm: float = -5000.0
    y_max_mm: float = 5000.0
    z_min_mm: float = -1000.0
    z_max_mm: float = 4000.0

    def __post_init__(self) -> None:
        for axis in "xyz":
            low, high = getattr(self, f"{axis}_min_mm"), getattr(self, f"{axis}_max_mm")
            if not high > low:
                raise ValueError(f"{axis}_max_mm ({high:g}) must be greater than "
                                 f"{axis}_min_mm ({low:g})")

    @cached_property
    def box(self) -> Box:
        return Box((self.x_min_mm, self.y_min_mm, self.z_min_mm),
                   (self.x_max_mm, self.y_max_mm, self.z_max_mm))

    def contains(self, xyz: Sequence[float] | np.ndarray) -> bool:
        """Inside, with every coordinate finite."""
        return self.box.contains(xyz)
