"""What a solve is asked to do (``solve.solve``, ``zoom_fit.solve_zooms``): plain data, so that
the service can hand it to the solving process without loading the solvers."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from common.camera import Pose
from common.passpoints import Track

Method = Literal["auto", "cmaes", "simplex"]


@dataclass(frozen=True)
class Options:
    method: Method = "auto"
    initial: Pose | None = None
    focal_mm: float = 3.8
    fit_focal: bool = False
    track: Track | None = None
    max_time_offset_s: float = 0.5
    inlier_px: float = 10.0
    max_mean_error_px: float = 20.0
    min_inlier_fraction: float = 0.5
    seed: int = 1
