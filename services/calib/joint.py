"""Beyond the paper: fit the focal length and the camera-to-mocap clock offset with the pose.

A passpoint's image was taken at ``t`` on the camera clock; its marker was where the mocap
track was at ``t + time_offset_s`` (mocap clock). The offset is found on a grid first (a pose
refined per candidate offset), then refined jointly with the pose (and the focal length) by
least squares on the inliers.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from common.camera import Intrinsics, Pose, project, reprojection_px
from common.passpoints import Passpoints, Track
from services.calib.pnp import refine_lm

OFFSET_GRID_STEP_S = 0.01


@dataclass(frozen=True)
class JointFit:
    pose: Pose
    focal_px: float
    time_offset_s: float | None
    evaluations: int


def best_offset_on_grid(pose: Pose, points: Passpoints, track: Track, intr: Intrinsics,
                        max_offset_s: float) -> tuple[float, Pose]:
    """The grid offset whose refined pose reprojects best (mean px), and that pose."""
    assert points.times_s is not None
    best = (np.inf, 0.0, pose)
    for offset in np.arange(-max_offset_s, max_offset_s + 1e-9, OFFSET_GRID_STEP_S):
        world = track.at(points.times_s + offset)
        candidate = refine_lm(pose, world, points.pixels, intr)
        error = float(np.mean(np.minimum(reprojection_px(candidate, world, points.pixels, intr),
                                         1e4)))
        if error < best[0]:
            best = (error, float(offset), candidate)
    return best[1], best[2]


def refine_jointly(pose: Pose, points: Passpoints, intr: Intrinsics, *, fit_focal: bool,
                   track: Track | None = None, time_offset_s: float = 0.0) -> JointFit:
    """Least squares over the pose and, as asked, the focal length and the clock offset."""
    fit_offset = track is not None
    if track is not None:
        if points.times_s is None:
            raise ValueError("a clock offset needs passpoint times")
        # UNIX times carry ~0.2 µs resolution: too coarse for the finite differences that
        # give the offset's derivative, so work in seconds since the first passpoint
        t0 = float(points.times_s.min())
        points = Passpoints(points.world_mm, points.pixels, points.times_s - t0)
        track = Track(track.times_s - t0, track.xyz_mm)
    from scipy.optimize import least_squares  # 0.4 s to import: only for a joint fit
    from scipy.spatial.transform import Rotation

    start = np.concatenate([Rotation.from_matrix(pose.rotation).as_rotvec(), pose.position,
                            [intr.focal_px] if fit_focal else [],
                            [time_offset_s] if fit_offset else []])
    scale = np.concatenate([[0.01] * 3, [10.0] * 3, [10.0] if fit_focal else [],
                            [0.005] if fit_offset else []])

    def unpack(p: np.ndarray) -> tuple[Pose, Intrinsics, float]:
        rotation = Rotation.from_rotvec(p[0:3]).as_matrix()
        focal = p[6] if fit_focal else intr.focal_px
        offset = p[-1] if fit_offset else 0.0
        return Pose.from_matrix(rotation, p[3:6]), intr.with_focal(float(focal)), float(offset)

    def world_at(offset: float) -> np.ndarray:
        if track is None or points.times_s is None:
            return points.world_mm
        return track.at(points.times_s + offset)

    def residuals(p: np.ndarray) -> np.ndarray:
        candidate, intr_p, offset = unpack(p)
        world = world_at(offset)
        uv = project(world, candidate, intr_p)
        return np.nan_to_num(uv - points.pixels, nan=1e4).ravel()

    result = least_squares(residuals, start, x_scale=scale, method="lm")
    fitted, intr_fit, offset = unpack(result.x)
    return JointFit(fitted, intr_fit.focal_px, offset if fit_offset else None, int(result.nfev))
