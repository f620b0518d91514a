"""Where a robot can be: anything outside (a reflection, a glitch, a bad sample) is ignored."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np


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

    def contains(self, xyz: Sequence[float] | np.ndarray) -> bool:
        """Inside, with every coordinate finite (up to QTM's rate: plain floats, no numpy)."""
        x, y, z = (float(c) for c in xyz)
        return (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)
                and self.x_min_mm <= x <= self.x_max_mm and self.y_min_mm <= y <= self.y_max_mm
                and self.z_min_mm <= z <= self.z_max_mm)
