"""The lens across the zoom range from passpoints taken at several zoom steps (pure): one
camera pose shared by every zoom (the head held at one pan and tilt), a focal length per zoom
and the lens's distortion per zoom (OpenCV's k1, k2, p1, p2, k3), by least squares over every
passpoint at once.

Start: the pose and the clock offset of the widest zoom's own solve (``solve.solve``, which
fits its focal length too); each other zoom's focal length in closed form from that pose
(pixels off the centre are linear in the focal length). Distortion starts at none and is held
near none by a weak prior (``PRIOR_PX`` pixels per unit coefficient): where the picture is
wide the passpoints decide it; at a long zoom, where it moves no pixel, it stays ≈ 0 instead of
wandering. A robust loss first, then passpoints farther than ``inlier_px`` from the fit are
left out and the fit repeats on the rest.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from common.camera import Intrinsics, Pose, project
from common.data_sheet import AXIS_215_PICTURE_PX
from common.lens import NO_DISTORTION
from common.passpoints import AtZoom, CalibrationError, Passpoints
from common.ptz_lens import Distortion, PtzLens, measured_lens
from services.calib.solve import Options, Solution, solve

PRIOR_PX = np.array([0.5, 0.5, 0.5, 0.5, 5.0])  # in a 704-wide picture: scaled with the width
ROUNDS = 3
MIN_PER_ZOOM = 6
POSE_PARAMS, LENS_PARAMS = 8, 6  # rotation vector, position, principal point (u, v); focal +
                                 # five coefficients per zoom
PRINCIPAL_PRIOR = 0.02  # px of residual per px of the principal point from the centre: it is
                        # the zooms that place it (pixels move away from it as the focal grows)


@dataclass(frozen=True)
class ZoomFit:
    pose: Pose  # the head's pose at the hold (pan and tilt of the collection)
    zooms: tuple[int, ...]
    focals_px: tuple[float, ...]  # in pixels of the picture the passpoints are in
    distortions: tuple[Distortion, ...]
    residuals_px: tuple[np.ndarray, ...]  # every passpoint's, per zoom
    inliers: tuple[np.ndarray, ...]  # indices per zoom
    evaluations: int
    picture_px: tuple[int, int] = AXIS_215_PICTURE_PX
    principal_px: tuple[float, float] | None = None  # None: the picture's centre

    def lens(self) -> PtzLens:
        return measured_lens(list(zip(self.zooms, self.focals_px, self.distortions,
                                      strict=True)), width_px=self.picture_px[0],
                             height_px=self.picture_px[1], principal_px=self.principal_px)

    def at_zoom(self) -> list[dict]:
        """Per zoom: the step, focal length, distortion, inliers and their mean error."""
        return [{"zoom": z, "focal_px": round(f, 2), "distortion": [round(c, 6) for c in d],
                 "passpoints": len(self.inliers[i]), "mean_error_px": round(
                     self.mean_error_px(i), 4)}
                for i, (z, f, d) in enumerate(zip(self.zooms, self.focals_px, self.distortions,
                                                  strict=True))]

    def report(self) -> dict:
        """What ``stb calib solve`` prints (JSON) and the calib service stores."""
        return {"position_mm": [round(v, 3) for v in self.pose.position.tolist()],
                "orientation_deg": [round(v, 5) for v in (self.pose.rx_deg, self.pose.ry_deg,
                                                          self.pose.rz_deg)],
                "mean_error_px": round(self.mean_error_px(), 4), "method": "zooms",
                "evaluations": self.evaluations, "lens": self.at_zoom(),
                "picture_px": list(self.picture_px),
                "principal_px": None if self.principal_px is None else [
                    round(c, 2) for c in self.principal_px],
                "residuals_px": {str(z): [round(float(r), 3) for r in self.residuals_px[i]]
                                 for i, z in enumerate(self.zooms)}}

    def mean_error_px(self, i: int | None = None) -> float:
        """Over the inliers of zoom ``i``, or of every zoom."""
        picked = range(len(self.zooms)) if i is None else [i]
        errors = np.concatenate([self.residuals_px[k][self.inliers[k]] for k in picked])
        return float(np.mean(errors)) if len(errors) else float("inf")


def closed_form_focal_px(pose: Pose, world_mm: np.ndarray, pixels: np.ndarray,
                         intr: Intrinsics) -> float:
    """The focal length that puts the passpoints nearest their pixels for a known pose
    (pinhole: u − c_u = f · y/x, v − c_v = f · aspect · z/x; least squares over u and v);
    ``intr``: the picture (its focal length is not used)."""
    cam = pose.to_camera(world_mm)
    ahead = cam[:, 0] > 0
    if ahead.sum() < 2:
        raise CalibrationError("the passpoints are behind the camera")
    cam, px = cam[ahead], pixels[ahead]
    unit = intr.with_focal(1.0)
    a = np.concatenate([cam[:, 1] / cam[:, 0] * unit.fy_px, cam[:, 2] / cam[:, 0] * unit.fz_px])
    b = np.concatenate([px[:, 0] - intr.cy_px, px[:, 1] - intr.cz_px])
    return float(a @ b / (a @ a))


def fit_zooms(sets: list[AtZoom], pose: Pose, focals_px: list[float], *,
              picture_px: tuple[int, int] = AXIS_215_PICTURE_PX, inlier_px: float = 10.0
              ) -> ZoomFit:
    """The joint fit, from a start ``pose`` and a focal length per set (pixels of a
    ``picture_px`` picture)."""
    from scipy.optimize import least_squares  # only to fit
    from scipy.spatial.transform import Rotation

    if len(sets) < 2:
        raise CalibrationError("a lens across the zoom range needs passpoints at two or more "
                               "zoom steps")
    for s in sets:
        if len(s.pixels) < MIN_PER_ZOOM:
            raise CalibrationError(f"zoom {s.zoom}: {len(s.pixels)} passpoints, at least "
                                   f"{MIN_PER_ZOOM} needed")
    centre = np.array(picture_px, dtype=float) / 2
    scale_px = picture_px[0] / AXIS_215_PICTURE_PX[0]  # the prior in the same angles
    start = np.concatenate([Rotation.from_matrix(pose.rotation).as_rotvec(), pose.position,
                            centre, *[[f, *NO_DISTORTION] for f in focals_px]])
    scale = np.concatenate([[0.01] * 3, [10.0] * 3, [2.0, 2.0],
                            *[[0.05 * f, 0.01, 0.01, 0.001, 0.001, 0.01] for f in focals_px]])
    kept = [np.arange(len(s.pixels)) for s in sets]

    def unpack(p: np.ndarray) -> tuple[Pose, list[Intrinsics]]:
        fitted = Pose.from_matrix(Rotation.from_rotvec(p[0:3]).as_matrix(), p[3:6])
        principal = (float(p[6]), float(p[7]))
        lenses = []
        for i in range(len(sets)):
            f, *d = p[POSE_PARAMS + LENS_PARAMS * i: POSE_PARAMS + LENS_PARAMS * (i + 1)]
            lenses.append(Intrinsics(float(f), *picture_px, principal_px=principal,
                                     distortion=(d[0], d[1], d[2], d[3], d[4])))
        return fitted, lenses

    def residuals(p: np.ndarray) -> np.ndarray:
        fitted, lenses = unpack(p)
        parts = [np.nan_to_num(project(s.world_mm[k], fitted, intr) - s.pixels[k],
                               nan=1e3).ravel()
                 for s, intr, k in zip(sets, lenses, kept, strict=True)]
        prior = [PRIOR_PX * scale_px * np.asarray(intr.distortion) for intr in lenses]
        prior.append(PRINCIPAL_PRIOR * (p[6:8] - centre))
        return np.concatenate(parts + prior)

    evaluations = 0
    for round_ in range(ROUNDS):
        result = least_squares(residuals, start, x_scale=scale, method="trf",
                               loss="soft_l1" if round_ == 0 else "linear", f_scale=2.0)
        start, evaluations = result.x, evaluations + int(result.nfev)
        fitted, lenses = unpack(start)
        errors = [np.nan_to_num(np.linalg.norm(project(s.world_mm, fitted, intr) - s.pixels,
                                               axis=1), nan=np.inf)
                  for s, intr in zip(sets, lenses, strict=True)]
        again = [np.flatnonzero(e <= inlier_px) for e in errors]
        if all(np.array_equal(a, k) for a, k in zip(again, kept, strict=True)):
            break
        kept = again
        for s, k in zip(sets, kept, strict=True):
            if len(k) < MIN_PER_ZOOM:
                raise CalibrationError(f"zoom {s.zoom}: only {len(k)} passpoints within "
                                       f"{inlier_px:g} px of the fit")
    fitted, lenses = unpack(start)
    order = np.argsort([s.zoom for s in sets])
    return ZoomFit(Pose.from_matrix(fitted.rotation, fitted.position),
                   tuple(sets[i].zoom for i in order),
                   tuple(lenses[i].focal_px for i in order),
                   tuple(lenses[i].distortion for i in order),
                   tuple(errors[i] for i in order), tuple(kept[i] for i in order), evaluations,
                   picture_px, lenses[0].principal_px)


def solve_zooms(by_zoom: dict[int, Passpoints], options: Options) -> tuple[ZoomFit, Solution]:
    """The lens and the pose from passpoints at two or more zoom steps: the widest zoom's own
    solve (pose, focal length, clock offset) starts the joint fit. Returns the fit and that
    first solve (its clock offset holds for every zoom: one camera, one clock)."""
    if len(by_zoom) < 2:
        raise CalibrationError("a lens across the zoom range needs passpoints at two or more "
                               "zoom steps")
    widest = min(by_zoom)
    seed = PtzLens().intrinsics(widest, *options.picture_px).focal_px  # the data sheet's
    first = solve(by_zoom[widest], replace(options, fit_focal=True, focal_px=seed))
    sets = []
    for zoom, points in sorted(by_zoom.items()):
        world = points.world_mm
        if options.track is not None and points.times_s is not None:
            world = options.track.at(points.times_s + (first.time_offset_s or 0.0))
        sets.append(AtZoom(zoom, world, points.pixels))
    picture = options.intrinsics()
    focals = [first.focal_px if s.zoom == widest else
              closed_form_focal_px(first.pose, s.world_mm, s.pixels, picture) for s in sets]
    fit = fit_zooms(sets, first.pose, focals, picture_px=options.picture_px,
                    inlier_px=options.inlier_px)
    if np.any(np.diff(fit.focals_px) <= 0):
        raise CalibrationError("the fitted focal lengths do not grow with the zoom step ("
                               + ", ".join(f"{z}: {f:.0f} px" for z, f in
                                           zip(fit.zooms, fit.focals_px, strict=True))
                               + "): too few passpoints at some zoom, or the zoom moved?")
    return fit, first
