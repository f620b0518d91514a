"""Passpoints in, camera pose out (paper §2.2, and past it).

Methods:
- ``auto`` (default, no guess needed): SQPnP inside RANSAC → Levenberg-Marquardt on the
  inliers, re-classifying every passpoint until the inliers settle.
- ``cmaes`` / ``simplex``: the paper's searches from a rough ``initial`` pose over its cost
  (mean pixel deviation, penalty behind the camera); passpoints farther than ``inlier_px``
  from the fit are then rejected and the search repeats on the rest, from its result.
Then, as asked, the focal length and the camera-to-mocap clock offset are fitted jointly.
Input that cannot give a trustworthy pose raises ``CalibrationError``; a wrong pose is
never returned.
"""

from __future__ import annotations

import contextlib
import time
from dataclasses import dataclass, field

import numpy as np

from common.camera import Intrinsics, Pose, reprojection_px
from common.data_sheet import AXIS_215_PICTURE_PX
from common.passpoints import CalibrationError, Passpoints, Track
from services.calib.cost import Fitness
from services.calib.joint import best_offset_on_grid, refine_jointly
from services.calib.options import Options
from services.calib.pnp import pose_std, ransac_seed, robust_refine
from services.calib.search import SearchMethod, search

MIN_PASSPOINTS = 6
JOINT_ROUNDS = 4
FOCAL_SEARCH_WIDTHS = (3.0 / 3.6, 60.0 / 3.6)  # focal lengths in picture widths: 3–60 mm on
                                              # the AXIS 215's 3.6 mm wide chip
FOCAL_SEARCH_STEPS = 32


@dataclass(frozen=True)
class Solution:
    pose: Pose
    focal_px: float
    mean_error_px: float
    evaluations: int
    seconds: float
    inliers: np.ndarray  # indices into the passpoints
    residuals_px: np.ndarray  # every passpoint's error at the solution (inf behind)
    method: str
    world_mm: np.ndarray  # the marker positions the pose was fitted to (track at the offset)
    time_offset_s: float | None = None
    position_std_mm: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    orientation_std_deg: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    fitness_curve: list[tuple[int, float]] = field(default_factory=list)
    picture_px: tuple[int, int] = AXIS_215_PICTURE_PX  # the snapshots' size

    def intrinsics(self) -> Intrinsics:
        return Intrinsics(self.focal_px, *self.picture_px)

    def report(self) -> dict:
        """The JSON that ``stb calib solve --json`` prints."""
        out = {
            "position_mm": [round(v, 3) for v in self.pose.position.tolist()],
            "orientation_deg": [round(v, 5) for v in
                                (self.pose.rx_deg, self.pose.ry_deg, self.pose.rz_deg)],
            "mean_error_px": round(self.mean_error_px, 4),
            "evaluations": self.evaluations,
            "seconds": round(self.seconds, 6),
            "inliers": self.inliers.tolist(),
            "rejected": sorted(set(range(len(self.residuals_px))) - set(self.inliers.tolist())),
            "method": self.method,
            "focal_px": round(self.focal_px, 2),
            "position_std_mm": [round(float(v), 3) for v in self.position_std_mm],
            "orientation_std_deg": [round(float(v), 5) for v in self.orientation_std_deg],
        }
        if self.time_offset_s is not None:
            out["time_offset_s"] = round(self.time_offset_s, 5)
        return out


def prepare(options: Options) -> None:
    """Import what the solve will need before it is timed (cma about 1 s with matplotlib,
    scipy.optimize 0.4 s; ``auto`` without a track or a focal fit needs neither)."""
    if options.method == "cmaes":
        import cma  # noqa: F401
    if options.method == "simplex" or options.fit_focal or options.track is not None:
        import scipy.optimize  # noqa: F401
        import scipy.spatial.transform  # noqa: F401


_warm = False


def warm_up() -> None:
    """Once per process, before the first solve that is timed (the solving worker's start,
    ``stb calib solve``, the benchmarks): the closed form on a few synthetic passpoints — the
    first calls into OpenCV and numpy cost milliseconds —, so that a reported solve time is
    the solve's, warm."""
    global _warm
    if _warm:
        return
    _warm = True
    from services.calib.synthetic import PAPER_POSE, passpoints

    with contextlib.suppress(CalibrationError):  # a warm-up only
        solve(passpoints(PAPER_POSE, np.random.default_rng(0), count=30)[0])


def solve(points: Passpoints, options: Options = Options()) -> Solution:
    prepare(options)  # imports are not the solve's time (warm_up: nor the first calls)
    started = time.perf_counter()
    check_input(points, options)
    intr = options.intrinsics()
    if options.fit_focal and options.method == "auto":
        intr = _focal_seed(points, options)
    points = _at_offset(points, options.track, 0.0)
    if options.method == "auto":
        pose, inliers, evaluations, curve = _auto(points, intr, options)
    else:
        pose, inliers, evaluations, curve = _search(points, intr, options, options.method)
    offset = None
    if options.fit_focal or options.track is not None:
        pose, intr, offset, inliers, more = _joint(pose, points, inliers, intr, options)
        evaluations += more
    pose = Pose.from_matrix(pose.rotation, pose.position)  # angles in (-180°, 180°]
    points = _at_offset(points, options.track, offset)
    residuals = reprojection_px(pose, points.world_mm, points.pixels, intr)
    position_std, orientation_std = (pose_std(pose, points.world_mm[inliers],
                                              points.pixels[inliers], intr)
                                     if len(inliers) > MIN_PASSPOINTS else
                                     (np.full(3, np.inf), np.full(3, np.inf)))
    solution = Solution(pose, intr.focal_px, float(np.mean(residuals[inliers])) if len(inliers)
                        else np.inf, evaluations, time.perf_counter() - started, inliers,
                        residuals, options.method, points.world_mm, offset, position_std,
                        orientation_std, curve, options.picture_px)
    check_result(solution, points, options)
    return solution


def check_input(points: Passpoints, options: Options) -> None:
    n = len(points)
    if n < MIN_PASSPOINTS:
        raise CalibrationError(f"{n} passpoints: a pose needs at least {MIN_PASSPOINTS}")
    values = [points.world_mm, points.pixels] + ([points.times_s] if points.times_s is not None
                                                 else [])
    bad = sorted({int(i) for v in values
                  for i in np.flatnonzero(~np.all(np.isfinite(v.reshape(n, -1)), axis=1))})
    if bad:
        raise CalibrationError(f"passpoints {bad[:10]} hold NaN or infinite values")
    if options.track is not None:
        if points.times_s is None:
            raise CalibrationError("a mocap track needs the passpoints' image times (column t)")
        if not options.track.covers(points.times_s):
            raise CalibrationError("the mocap track does not cover the passpoints' times "
                                   f"{points.times_s.min():.3f}–{points.times_s.max():.3f} s")
        world = options.track.at(points.times_s)
    else:
        world = points.world_mm
    spread = np.linalg.svd(world - world.mean(axis=0), compute_uv=False)
    if spread[1] < 1e-3 * max(spread[0], 1e-9) or spread[0] < 1.0:
        raise CalibrationError("the passpoints' world positions lie on one line (or one point): "
                               "move the marker across the camera's view, not along a line")
    if options.method != "auto" and options.initial is None:
        raise CalibrationError(f"method {options.method} starts from a rough pose: give an "
                               "initial guess, or use method auto, which needs none")
    if options.initial is not None and options.method != "auto":
        depth = options.initial.to_camera(world)[:, 0]
        if np.all(depth <= 0):
            raise CalibrationError("every passpoint is behind the camera at the initial guess "
                                   "(x ≤ 0 along its optical axis): check the guess's "
                                   "orientation, or use method auto, which needs no guess")
    if not 0 < options.focal_px < 1e5:
        raise CalibrationError(f"focal length {options.focal_px} px is not plausible")


def check_result(solution: Solution, points: Passpoints, options: Options) -> None:
    n, kept = len(points), len(solution.inliers)
    if kept < max(MIN_PASSPOINTS, int(np.ceil(options.min_inlier_fraction * n))):
        raise CalibrationError(
            f"only {kept} of {n} passpoints agree on one pose within {options.inlier_px:g} px: "
            "check the passpoints (wrong pairs, another marker in view, clock offset?)")
    if not solution.mean_error_px <= options.max_mean_error_px:
        raise CalibrationError(f"best pose leaves a mean error of {solution.mean_error_px:.1f} px"
                               f" (limit {options.max_mean_error_px:g} px): not trustworthy")


def _auto(points: Passpoints, intr: Intrinsics, options: Options
          ) -> tuple[Pose, np.ndarray, int, list]:
    seeded = ransac_seed(points.world_mm, points.pixels, intr, options.inlier_px, options.seed)
    if seeded is None:
        raise CalibrationError("no pose is consistent with enough passpoints (RANSAC found no "
                               "consensus): check the passpoints and the focal length")
    pose, inliers = robust_refine(seeded[0], points.world_mm, points.pixels, intr,
                                  options.inlier_px)
    return pose, inliers, 0, []


def _search(points: Passpoints, intr: Intrinsics, options: Options, method: SearchMethod
            ) -> tuple[Pose, np.ndarray, int, list]:
    assert options.initial is not None
    p = options.initial
    start = np.array([p.x_mm, p.y_mm, p.z_mm, p.rx_deg, p.ry_deg, p.rz_deg])
    fitness = Fitness(points.world_mm, points.pixels, intr)
    best = search(method, fitness, start, options.seed)
    pose = Pose(*best)
    inliers = np.flatnonzero(reprojection_px(pose, points.world_mm, points.pixels, intr)
                             <= options.inlier_px)
    if MIN_PASSPOINTS <= len(inliers) < len(points):
        kept = Fitness(points.world_mm[inliers], points.pixels[inliers], intr)
        best = search(method, kept, best, options.seed + 1,
                      step=np.array([50.0, 50.0, 50.0, 2.0, 2.0, 2.0]))
        pose = Pose(*best)
        inliers = np.flatnonzero(reprojection_px(pose, points.world_mm, points.pixels, intr)
                                 <= options.inlier_px)
        return pose, inliers, fitness.evaluations + kept.evaluations, fitness.history
    return pose, inliers, fitness.evaluations, fitness.history


def _joint(pose: Pose, points: Passpoints, inliers: np.ndarray, intr: Intrinsics,
           options: Options) -> tuple[Pose, Intrinsics, float | None, np.ndarray, int]:
    """Fit pose + focal and/or clock offset on the inliers, re-classify, repeat until the
    inliers settle (a wrong start focal or offset leaves good points out at first)."""
    offset: float | None = 0.0
    if options.track is not None:
        offset, pose = best_offset_on_grid(pose, points.subset(inliers), options.track, intr,
                                           options.max_time_offset_s)
    evaluations = 0
    for _ in range(JOINT_ROUNDS):
        fit = refine_jointly(pose, points.subset(inliers), intr, fit_focal=options.fit_focal,
                             track=options.track, time_offset_s=offset or 0.0)
        pose, intr, offset = fit.pose, intr.with_focal(fit.focal_px), fit.time_offset_s
        evaluations += fit.evaluations
        again = np.flatnonzero(_residuals(pose, points, intr, options.track, offset)
                               <= options.inlier_px)
        if np.array_equal(again, inliers) or len(again) < MIN_PASSPOINTS:
            break
        inliers = again
    return pose, intr, offset, inliers, evaluations


def _at_offset(points: Passpoints, track: Track | None, offset: float | None) -> Passpoints:
    """With a track, the passpoints' marker positions are the track at image time + offset."""
    if track is None:
        return points
    assert points.times_s is not None
    return points.with_world(track.at(points.times_s + (offset or 0.0)))


def _residuals(pose: Pose, points: Passpoints, intr: Intrinsics, track: Track | None,
               offset: float | None) -> np.ndarray:
    points = _at_offset(points, track, offset)
    return reprojection_px(pose, points.world_mm, points.pixels, intr)


def _focal_seed(points: Passpoints, options: Options) -> Intrinsics:
    """For a focal-length fit: the lens focal length (on a geometric grid over a PTZ zoom's
    range) at which RANSAC finds the most inliers with the lowest error."""
    best: tuple[int, float, float] = (-1, np.inf, options.focal_px)
    width = options.picture_px[0]
    shortest, longest = (width * w for w in FOCAL_SEARCH_WIDTHS)
    for focal in np.geomspace(shortest, longest, FOCAL_SEARCH_STEPS):
        intr = options.intrinsics(float(focal))
        seeded = ransac_seed(points.world_mm, points.pixels, intr, options.inlier_px,
                             options.seed)
        if seeded is None:
            continue
        pose, inliers = seeded
        error = float(np.mean(reprojection_px(pose, points.world_mm[inliers],
                                              points.pixels[inliers], intr)))
        if (len(inliers), -error) > (best[0], -best[1]):
            best = (len(inliers), error, float(focal))
    return options.intrinsics(best[2])
