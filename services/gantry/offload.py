"""Gravity offload (paper §4): what a horizontal crane-to-robot error does to the cable's pull.

A cable of length L from the crane down to the robot, offset horizontally by d, leans by
θ = asin(d / L). Of its tension, cos θ still pulls up — the vertical force drops by 1 − cos θ —
and sin θ pulls sideways. The paper: a 10 cm error (on a 2 m cable) changes the vertical force
by < 1 % and adds ~5 % horizontal force.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Offload:
    horizontal_error_mm: float
    vertical_loss_pct: float
    horizontal_share_pct: float
    warning: bool


def offload(horizontal_error_mm: float, cable_length_mm: float,
            warn_horizontal_pct: float = 5.0) -> Offload:
    if cable_length_mm <= 0:
        raise ValueError("cable length must be positive")
    d = min(abs(horizontal_error_mm), cable_length_mm)
    theta = math.asin(d / cable_length_mm)
    vertical_loss = 100.0 * (1.0 - math.cos(theta))
    horizontal = 100.0 * math.sin(theta)
    return Offload(abs(horizontal_error_mm), vertical_loss, horizontal,
                   horizontal > warn_horizontal_pct)
