"""Commissioning's arithmetic (pure): the crane's frame from its reports and the motion
capture's marker on its carriage, and the tracking camera's lens and mount from markers the
motion capture knows, seen from many crane positions. Every value comes with its 1σ spread
(from the fit's Jacobian and its residual, as Kalibr reports them).

Frame: Umeyama's closed form (as ``evo``'s ``umeyama_alignment``) gives the orthogonal map —
a reflection allowed, since a crane may count an axis the other way — and a least-squares
polish gives the spreads; the similarity scale is kept as a diagnostic (a wrong register scale
shows up there). The pattern must span two axes (collinear stops are refused).

Camera: focal length, principal point, OpenCV's k1, k2, p1, p2, k3, the image's yaw against
the crane's axes and the lens's offset from the crane's reported point, fitted together to the
pixels of markers at known world positions (``scipy.optimize.least_squares``), the lens's
height given (the crane's marker sits at it). Markers at two heights separate the lens's
offset (its pixels shrink with depth) from the principal point (which does not).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import OptimizeResult, least_squares

from common.crane_frame import CraneFrame
from common.tracking_camera import TrackingCameraModel


class FitRefused(ValueError):
    """A fit that must not be used; the message says why and what to do."""


@dataclass(frozen=True)
class FrameFit:
    frame: CraneFrame
    origin_sd_mm: tuple[float, float]
    yaw_sd_deg: float
    residual_rms_mm: float
    residual_max_mm: float
    scale: float  # the similarity fit's scale: 1 for a crane that counts millimetres
    stops: int


@dataclass(frozen=True)
class CameraFit:
    camera: TrackingCameraModel
    spreads: dict[str, float]  # 1σ of each fitted value, by name
    residual_rms_px: float
    residual_max_px: float
    observations: int


@dataclass(frozen=True)
class Sighting:
    """A marker at a known world position seen at a pixel while the crane stood somewhere."""

    crane_xy: np.ndarray  # the crane's reported point in the world (mm)
    marker_xyz: np.ndarray  # the marker in the world (mm), from the motion capture
    pixel: np.ndarray  # (u, v)


def fit_frame(crane_xy: np.ndarray, marker_xy: np.ndarray, *, max_residual_mm: float = 10.0,
              max_scale_error: float = 0.01) -> FrameFit:
    """The crane's frame from (N, 2) reported positions (its own frame) and (N, 2) world
    positions of the marker on its carriage at the same moments (at rest)."""
    crane_xy, marker_xy = np.asarray(crane_xy, float), np.asarray(marker_xy, float)
    if len(crane_xy) < 3:
        raise FitRefused(f"{len(crane_xy)} stops: the frame needs at least 3")
    c_mean, w_mean = crane_xy.mean(axis=0), marker_xy.mean(axis=0)
    c, w = crane_xy - c_mean, marker_xy - w_mean
    spread = np.linalg.svd(c, compute_uv=False)
    if spread[-1] < 0.1 * spread[0] or spread[-1] < 1.0:
        raise FitRefused("the stops lie on a line: the frame needs a pattern that spans both "
                         "axes (a larger --box?)")
    u, s, vt = np.linalg.svd(w.T @ c)
    linear = u @ vt  # orthogonal, a reflection allowed (Umeyama without the sign fix)
    scale = float(s.sum() / (c * c).sum())
    first = CraneFrame.from_linear(w_mean - linear @ c_mean, linear)
    frame, sd = _polish_frame(first, crane_xy, marker_xy)
    residuals = np.hypot(*(frame.to_world(crane_xy) - marker_xy).T)
    fit = FrameFit(frame, (sd[0], sd[1]), sd[2], float(np.sqrt(np.mean(residuals ** 2))),
                   float(residuals.max()), scale, len(crane_xy))
    if abs(scale - 1.0) > max_scale_error:
        raise FitRefused(f"the crane counts {scale:.4f} mm per mm of the motion capture's: is "
                         "[gantry.crane] units_per_mm the controller's?")
    if fit.residual_rms_mm > max_residual_mm:
        raise FitRefused(f"the crane's reports and its marker disagree by {fit.residual_rms_mm:.1f}"
                         f" mm rms after the fit (at most {max_residual_mm:g}): is the marker "
                         "fixed to the carriage, and did the crane stand still at each stop?")
    return fit


def _polish_frame(first: CraneFrame, crane_xy: np.ndarray, marker_xy: np.ndarray
                  ) -> tuple[CraneFrame, np.ndarray]:
    """Least squares on origin and yaw (the flips fixed): the frame and each value's 1σ."""
    def frame_of(p: np.ndarray) -> CraneFrame:
        return CraneFrame(origin_mm=(float(p[0]), float(p[1])), yaw_deg=float(p[2]),
                          flip_x=first.flip_x, flip_y=first.flip_y)

    def residuals(p: np.ndarray) -> np.ndarray:
        return (frame_of(p).to_world(crane_xy) - marker_xy).ravel()

    result = least_squares(residuals, [*first.origin_mm, first.yaw_deg], x_scale=[100, 100, 1])
    return frame_of(result.x), _spreads(result)


_CAMERA = ("focal_mm", "cx_px", "cy_px", "k1", "k2", "p1", "p2", "k3", "yaw_deg",
           "offset_x_mm", "offset_y_mm")
_SCALES = (0.1, 5.0, 5.0, 0.05, 0.05, 0.001, 0.001, 0.05, 1.0, 10.0, 10.0)


def fit_camera(sightings: list[Sighting], nominal: TrackingCameraModel, frame: CraneFrame,
               height_mm: float, *, max_residual_px: float = 1.0, distortion: bool = True
               ) -> CameraFit:
    """The tracking camera's lens and mount from ``sightings``, starting from ``nominal``
    (its focal length and pixel pitch from the data sheet, centred, undistorted, aligned).
    ``distortion=False``: a first fit without it (the lens bends only the image's edges).
    OpenCV's k3 stays 0 (its ``CALIB_FIX_K3``): behind a 6–12 mm lens on this chip the image's
    corners lie at most 0.45 of the focal length off the axis, where k3 of the size real lenses
    have moves a pixel by a tenth of one, while fitting it let k2 and k3 trade off and bent the
    corners by up to 1.7 px (tests/gantry/test_geometry_fit.py, lenses drawn at 6.6–10.8 mm)."""
    free = [i for i, name in enumerate(_CAMERA) if name != "k3"
            and (distortion or name not in ("k1", "k2", "p1", "p2"))]
    if len(sightings) < len(free):
        raise FitRefused(f"{len(sightings)} sightings: the camera needs at least {len(free)}")
    crane = np.array([s.crane_xy for s in sightings])
    markers = np.array([s.marker_xyz for s in sightings])
    pixels = np.array([s.pixel for s in sightings])
    base = nominal.model_copy(update={"height_mm": height_mm})

    def camera_of(p: np.ndarray) -> TrackingCameraModel:
        return base.model_copy(update={
            "focal_mm": float(p[0]), "principal_px": (float(p[1]), float(p[2])),
            "distortion": tuple(float(k) for k in p[3:8]), "yaw_deg": float(p[8]),
            "offset_mm": (float(p[9]), float(p[10]))})

    cx, cy = nominal.principal
    start = np.array([nominal.focal_mm, cx, cy, 0, 0, 0, 0, 0, 0, 0, 0], dtype=float)

    def full(p: np.ndarray) -> np.ndarray:
        values = start.copy()
        values[free] = p
        return values

    def residuals(p: np.ndarray) -> np.ndarray:
        camera = camera_of(full(p))
        seen = np.vstack([camera.project(m, c, frame)[0] for m, c in zip(markers, crane,
                                                                          strict=True)])
        return np.nan_to_num(seen - pixels, nan=1e3).ravel()

    result = least_squares(residuals, start[free], x_scale=np.array(_SCALES)[free],
                           loss="soft_l1", f_scale=1.0)
    left = np.hypot(*result.fun.reshape(-1, 2).T)
    spreads = dict.fromkeys(_CAMERA, 0.0)
    spreads.update(zip([_CAMERA[i] for i in free], _spreads(result), strict=True))
    fit = CameraFit(camera_of(full(result.x)), spreads, float(np.sqrt(np.mean(left ** 2))),
                    float(left.max()), len(sightings))
    if fit.residual_rms_px > max_residual_px:
        raise FitRefused(f"the camera's model leaves {fit.residual_rms_px:.2f} px rms (at most "
                         f"{max_residual_px:g}): did a marker move, or is another spot taken "
                         "for it?")
    return fit


def _spreads(result: OptimizeResult) -> np.ndarray:
    """1σ of each parameter: the residual's variance times (JᵀJ)⁻¹."""
    jac, fun = result.jac, result.fun
    dof = max(len(fun) - jac.shape[1], 1)
    variance = float(fun @ fun) / dof
    return np.sqrt(np.diag(np.linalg.pinv(jac.T @ jac)) * variance)


def distortion_difference_px(a: TrackingCameraModel, b: TrackingCameraModel,
                             steps: int = 25) -> float:
    """The largest distance, anywhere in the image, between where two lenses bend a ray (each
    about its own principal point): how far apart two distortion estimates are, in pixels."""
    us = np.linspace(0, a.width_px, steps)
    vs = np.linspace(0, a.height_px, steps)
    pixels = np.array([(u, v) for u in us for v in vs])
    depth = a.height_mm - 0.0

    def bent(camera: TrackingCameraModel) -> np.ndarray:
        chip = camera.chip_px(depth)
        rays = np.array([camera.ray(u, v, depth) for u, v in pixels])  # undistorted
        straight = np.asarray(camera.principal) + rays * chip
        return pixels - straight

    return float(np.hypot(*(bent(a) - bent(b)).T).max())
