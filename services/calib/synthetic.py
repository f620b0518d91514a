"""Synthetic passpoints from a known pose, spread as in the paper (2–7 m from the camera, all
over the image), for the tests and the benchmarks."""

from __future__ import annotations

import numpy as np

from common.camera import Intrinsics, Pose, project, undistort_pixels
from common.passpoints import AtZoom, Passpoints, Track
from common.ptz_lens import PtzLens, axis_215

PAPER_POSE = Pose(3413.0, 1093.0, 2163.0, 197.0, 27.0, 159.0)
"""Near the paper's optimum for its camera (Table 2)."""
PAPER_GUESS = Pose(2000.0, 500.0, 3000.0, 180.0, 0.0, 180.0)
"""The paper's rough initial guess (Table 2)."""


def points_in_view(pose: Pose, intr: Intrinsics, rng: np.random.Generator, count: int,
                   depth_mm: tuple[float, float] = (2000.0, 7000.0), margin_px: float = 10.0
                   ) -> np.ndarray:
    """World points that the camera sees anywhere in its image, ``depth_mm`` along its axis."""
    u = rng.uniform(margin_px, intr.width_px - margin_px, count)
    v = rng.uniform(margin_px, intr.height_px - margin_px, count)
    d = rng.uniform(*depth_mm, count)
    camera = np.column_stack([d, (u - intr.cy_px) / intr.fy_px * d,
                              (v - intr.cz_px) / intr.fz_px * d])
    return pose.to_world(camera)


def passpoints(pose: Pose, rng: np.random.Generator, count: int = 100, noise_px: float = 2.0,
               focal_mm: float = 3.8, wrong_fraction: float = 0.0) -> tuple[Passpoints,
                                                                              np.ndarray]:
    """``count`` passpoints with Gaussian pixel noise; a fraction of them paired with a wrong
    pixel (≥ 40 px away). Returns the passpoints and the indices of the wrong ones."""
    intr = axis_215(focal_mm)
    world = points_in_view(pose, intr, rng, count)
    pixels = project(world, pose, intr) + rng.normal(0.0, noise_px, (count, 2))
    wrong = np.sort(rng.choice(count, int(round(wrong_fraction * count)), replace=False))
    for i in wrong:
        while True:
            candidate = rng.uniform([0, 0], [intr.width_px, intr.height_px])
            if np.linalg.norm(candidate - pixels[i]) >= 40.0:
                pixels[i] = candidate
                break
    return Passpoints(world, pixels), wrong


def moving_marker(pose: Pose, rng: np.random.Generator, *, count: int = 100,
                  speed_mm_s: float = 400.0, offset_s: float = 0.1, noise_px: float = 2.0,
                  track_rate_hz: float = 100.0, track_noise_mm: float = 0.5
                  ) -> tuple[Passpoints, Track]:
    """A marker carried at constant speed between points in view; the camera's clock runs
    ``offset_s`` behind the mocap's (mocap time = camera time + offset_s). Returns passpoints
    with image times (camera clock) and the mocap track."""
    intr = axis_215(3.8)
    waypoints = points_in_view(pose, intr, rng, 40, margin_px=40.0)
    legs = np.linalg.norm(np.diff(waypoints, axis=0), axis=1) / speed_mm_s
    key_t = np.concatenate([[0.0], np.cumsum(legs)])
    mocap_t0 = 1000.0
    t = np.arange(0.0, key_t[-1], 1.0 / track_rate_hz)
    xyz = np.column_stack([np.interp(t, key_t, waypoints[:, i]) for i in range(3)])
    track = Track(t + mocap_t0, xyz + rng.normal(0.0, track_noise_mm, xyz.shape))
    image_t = np.sort(rng.uniform(1.0, key_t[-1] - 1.0, count))
    world = np.column_stack([np.interp(image_t, key_t, waypoints[:, i]) for i in range(3)])
    pixels = project(world, pose, intr) + rng.normal(0.0, noise_px, (count, 2))
    return Passpoints(world, pixels, image_t + mocap_t0 - offset_s), track


def zoom_passpoints(pose: Pose, lens: PtzLens, zooms: list[int], rng: np.random.Generator,
                    count: int = 40, noise_px: float = 0.3,
                    depth_mm: tuple[float, float] = (2000.0, 7000.0)) -> list[AtZoom]:
    """``count`` passpoints at each zoom step, seen through ``lens`` (its focal length at the
    step and its distortion) anywhere in the picture, corners included."""
    sets = []
    for zoom in zooms:
        intr = lens.intrinsics(zoom)
        seen = rng.uniform([1.0, 1.0], [intr.width_px - 1.0, intr.height_px - 1.0], (count, 2))
        sets.append(seen_at(pose, intr, seen, rng, noise_px, depth_mm, zoom))
    return sets


def seen_at(pose: Pose, intr: Intrinsics, seen: np.ndarray, rng: np.random.Generator,
            noise_px: float, depth_mm: tuple[float, float] = (2000.0, 7000.0),
            zoom: int = 0) -> AtZoom:
    """Passpoints whose markers the camera sees at the pixels ``seen`` through ``intr`` (its
    distortion too), ``depth_mm`` along its axis, with Gaussian pixel noise."""
    straight = undistort_pixels(seen, intr)
    d = rng.uniform(*depth_mm, len(seen))
    world = pose.to_world(np.column_stack([d, (straight[:, 0] - intr.cy_px) / intr.fy_px * d,
                                           (straight[:, 1] - intr.cz_px) / intr.fz_px * d]))
    return AtZoom(zoom, world, seen + rng.normal(0.0, noise_px, seen.shape))
