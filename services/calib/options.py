"""What a solve is asked to do (``solve.solve``, ``zoom_fit.solve_zooms``): plain data, so that
the service can hand it to the solving process without loading the solvers."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

from common.camera import Intrinsics, Pose
from common.data_sheet import AXIS_215_PICTURE_PX
from common.passpoints import Track
from common.ptz_lens import axis_215_px

Method = Literal["auto", "cmaes", "simplex"]


@dataclass(frozen=True)
class Options:
    method: Method = "auto"
    initial: Pose | None = None
    focal_px: float = axis_215_px(3.8)  # the AXIS 215 at its widest (Table 1)
    picture_px: tuple[int, int] = AXIS_215_PICTURE_PX  # the snapshots' size
    fit_focal: bool = False
    track: Track | None = None
    max_time_offset_s: float = 0.5
    inlier_px: float = 10.0
    max_mean_error_px: float = 20.0
    min_inlier_fraction: float = 0.5
    seed: int = 1

    @classmethod
    def in_picture(cls, picture_px: tuple[int, int], *, inlier_px: float = 10.0,
                   max_mean_error_px: float = 20.0, **rest: Any) -> Options:
        """Options for snapshots of ``picture_px`` with the pixel thresholds given for the
        AXIS 215's 704-wide picture (the settings' ``inlier_px``, ``max_mean_error_px``):
        scaled with the picture's width, so that they mean the same angles in any camera."""
        scale = picture_px[0] / AXIS_215_PICTURE_PX[0]
        return cls(picture_px=picture_px, inlier_px=inlier_px * scale,
                   max_mean_error_px=max_mean_error_px * scale, **rest)

    def intrinsics(self, focal_px: float | None = None) -> Intrinsics:
        """The camera's picture at ``focal_px`` (default the options' own)."""
        return Intrinsics(self.focal_px if focal_px is None else focal_px, *self.picture_px)
