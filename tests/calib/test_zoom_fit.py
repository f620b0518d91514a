"""The lens across the zoom range (pure): passpoints at several zoom steps of a lens drawn at
random — a zoom curve slow over most steps and steep at the end, barrel distortion at the wide
end fading towards the long end, in the sim's terms — fitted jointly with one pose."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np
import pytest

from common.camera import (
    Intrinsics,
    Pose,
    picture_pixel_aspect,
    pose_distance,
    project_camera,
    undistort_pixels,
)
from common.passpoints import CalibrationError, Passpoints
from common.ptz_lens import PtzLens, ZoomCurve, axis_215_px
from services.calib.solve import Options, solve
from services.calib.synthetic import PAPER_POSE, zoom_passpoints
from services.calib.zoom_fit import solve_zooms
from services.sim.settings import PtzCameraSettings

ZOOMS = [1, 1500, 3500, 5500, 7000, 8000, 9000, 9999]  # benchmarks.zoom_plan chose them
STEPS = [float(z) for z in range(1, 10000, 7)]  # every 7th zoom step, as the camera counts


def drawn_lens(rng: np.random.Generator) -> PtzLens:
    """A table of twelve points of a smooth, bent curve (no line, no power law the code knows
    of), and distortion at both ends, all drawn: focal lengths of 3.8 mm to 40–50 mm on the
    AXIS 215's chip, in pixels of its picture."""
    zooms = np.round(np.linspace(1, 9999, 12))  # whole steps, as a lab file would list them
    bend = rng.uniform(1.5, 3.0)
    long_mm = rng.uniform(40.0, 50.0)
    focal = 3.8 * (long_mm / 3.8) ** ((zooms / 9999) ** bend)
    wide = (rng.uniform(-0.35, -0.15), rng.uniform(0.03, 0.15), rng.uniform(-2e-3, 2e-3),
            rng.uniform(-2e-3, 2e-3), rng.uniform(-0.02, 0.02))
    long = [float(c) for c in rng.uniform(-0.05, 0.05, 5) * [1, 1, 0.01, 0.01, 0]]
    focal = focal * axis_215_px(1.0)
    return PtzLens(ZoomCurve(tuple(float(z) for z in zooms), tuple(float(f) for f in focal)),
                   (float(focal[0]), float(focal[-1])),
                   (wide, (long[0], long[1], long[2], long[3], long[4])))


def drawn_camera(rng: np.random.Generator, picture: tuple[int, int] = (1920, 1080)
                 ) -> dict[str, Any]:
    """A current PTZ camera as ``[[sim.cameras]]`` fields, every truth drawn: after the AXIS
    M5525-E's data sheet (1920 × 1080, a 1/2.8-inch chip, 4.7–47 mm, 10×), a chip 5.0–5.8 mm
    wide (its height as the picture's aspect has it: square pixels, or PAL's of a 4:3 chip in
    704 × 576), a wide end of 4.4–5.0 mm, 9–11× to the long end along
    a bent curve, the drawn lens's distortion, a principal point up to 25 px (in 1920) off the
    centre, and a head whose tilt axis and lens sit up to 20 mm off the pan axis."""
    chip_w = rng.uniform(5.0, 5.8)
    width, height = picture
    zooms = np.round(np.linspace(1, 9999, 12))
    wide_mm, ratio, bend = rng.uniform(4.4, 5.0), rng.uniform(9.0, 11.0), rng.uniform(1.5, 3.0)
    focal = wide_mm * ratio ** ((zooms / 9999) ** bend)
    distortions = drawn_lens(rng).distortions
    chip_h = chip_w * height / width / picture_pixel_aspect(width, height)  # f_v / f_u
    return {"picture_px": [width, height], "chip_mm": [chip_w, chip_h],
            "zoom_focal_mm": [[float(z), float(f)] for z, f in zip(zooms, focal, strict=True)],
            "distortion": list(distortions[0]), "distortion_long": list(distortions[1]),
            "principal_offset_px": [float(v) for v in rng.uniform(-25.0, 25.0, 2) * width / 1920],
            "tilt_axis_mm": [float(v) for v in rng.uniform(-20.0, 20.0, 3)],
            "optical_centre_mm": [float(v) for v in rng.uniform(-20.0, 20.0, 3)]}


def sim_camera(fields: dict[str, Any], mount: Pose = PAPER_POSE) -> PtzCameraSettings:
    """ptz1 as the sim holds it with these fields, on ``mount``: its truth (lens, head)."""
    return PtzCameraSettings(name="ptz1", port=0, **mount.fields(), **fields)


def as_passpoints(sets: list) -> dict[int, Passpoints]:
    return {s.zoom: Passpoints(s.world_mm, s.pixels) for s in sets}


EDGE_BAND = 0.05
"""Of the picture's width and height along its edges: where no passpoint need be (the corner
rule asks for them within 15 %), the fit extrapolates, and the distortion is judged on its own
bound. Synthetic collections with this rule (3 a corner, ``python -m
benchmarks.zoom_plan``): the largest error in the whole picture and without this band
(docs/calibration.md)."""


def distortion_error_px(fitted: Intrinsics, truth: Intrinsics, inset: float = 0.0) -> float:
    """The largest difference anywhere in the picture (but a band of ``inset`` of its width
    and height along its edges) between how the two lenses bend a ray (both at the true focal
    length: the focal length is judged on its own)."""
    w, h = truth.width_px - 1, truth.height_px - 1
    u, v = np.meshgrid(np.linspace(inset * w, (1 - inset) * w, 40),
                       np.linspace(inset * h, (1 - inset) * h, 32))
    seen = np.column_stack([u.ravel(), v.ravel()])
    straight = undistort_pixels(seen, truth)
    rays = np.column_stack([np.ones(len(seen)), (straight[:, 0] - truth.cy_px) / truth.fy_px,
                            (straight[:, 1] - truth.cz_px) / truth.fz_px])
    bent = project_camera(rays, replace(truth, distortion=fitted.distortion))
    return float(np.max(np.linalg.norm(bent - seen, axis=1)))


@pytest.mark.parametrize("seed", range(4))
def test_focal_within_2_percent_everywhere_and_distortion_within_1_px(seed: int) -> None:
    rng = np.random.default_rng(seed)
    truth = drawn_lens(rng)
    sets = zoom_passpoints(PAPER_POSE, truth, ZOOMS, rng, count=100)
    fit, _ = solve_zooms(as_passpoints(sets), Options())
    lens = fit.lens()
    focal_error = max(abs(lens.focal_px(z) / truth.focal_px(z) - 1) for z in STEPS)
    assert focal_error < 0.02, f"{100 * focal_error:.2f} %"
    assert distortion_error_px(lens.intrinsics(1), truth.intrinsics(1)) <= 1.0
    position, angle = pose_distance(fit.pose, PAPER_POSE)
    # as accurate as a single-zoom calibration of a lens without distortion, same passpoints
    plain = PtzLens(truth.curve)
    single = solve(as_passpoints(zoom_passpoints(PAPER_POSE, plain, [1], rng, 100))[1],
                   Options(fit_focal=True))
    single_position, single_angle = pose_distance(single.pose, PAPER_POSE)
    assert position <= max(2 * single_position, 2.0) and angle <= max(2 * single_angle, 0.02)
    assert fit.mean_error_px() < 0.6  # 0.3 px noise per axis: ≈ 0.38 px


PICTURES = [(1920, 1080), (1280, 720), (2560, 1440), (3840, 2160), (704, 576)]


@pytest.mark.parametrize("seed", range(4))
def test_a_camera_of_any_picture_is_measured_with_its_principal_point(seed: int) -> None:
    """A camera drawn with its picture (16:9 sizes up to 4K, or the AXIS 215's PAL one), chip,
    zoom range, distortion and principal point: the same bounds, the principal point within a
    pixel, from passpoints in that picture and nothing else."""
    rng = np.random.default_rng(100 + seed)
    picture = PICTURES[int(rng.integers(len(PICTURES)))]
    truth = sim_camera(drawn_camera(rng, picture)).lens()
    sets = zoom_passpoints(PAPER_POSE, truth, ZOOMS, rng, count=100,
                           noise_px=0.3 * picture[0] / 704)
    fit, _ = solve_zooms(as_passpoints(sets), Options.in_picture(picture))
    lens = fit.lens()
    assert (lens.width_px, lens.height_px) == picture
    focal_error = max(abs(lens.focal_px(z) / truth.focal_px(z) - 1) for z in STEPS)
    assert focal_error < 0.02, f"{picture}: {100 * focal_error:.2f} %"
    scale = picture[0] / 704  # the same angles at more pixels; the bounds of the system test
    assert distortion_error_px(lens.intrinsics(1), truth.intrinsics(1), EDGE_BAND) <= scale
    assert distortion_error_px(lens.intrinsics(1), truth.intrinsics(1)) <= 2 * scale
    wide = truth.intrinsics(1)
    assert fit.principal_px is not None
    assert np.hypot(fit.principal_px[0] - wide.cy_px, fit.principal_px[1] - wide.cz_px) <= scale
    position, angle = pose_distance(fit.pose, PAPER_POSE)
    assert position < 5.0 and angle < 0.05, (position, angle)


def test_the_straight_line_is_far_off_such_a_lens() -> None:
    """What the fit is for: the data sheet's line misses a bent curve by far more than 2 %."""
    truth = drawn_lens(np.random.default_rng(0))
    line = PtzLens()
    assert max(abs(line.focal_px(z) / truth.focal_px(z) - 1) for z in STEPS) > 0.3


def test_one_zoom_or_too_few_passpoints_at_one_is_refused_saying_why() -> None:
    rng = np.random.default_rng(5)
    truth = drawn_lens(rng)
    sets = as_passpoints(zoom_passpoints(PAPER_POSE, truth, [1, 9999], rng, count=40))
    with pytest.raises(CalibrationError, match="two or more zoom steps"):
        solve_zooms({1: sets[1]}, Options())
    few = {1: sets[1], 9999: Passpoints(sets[9999].world_mm[:4], sets[9999].pixels[:4])}
    with pytest.raises(CalibrationError, match="zoom 9999: 4 passpoints"):
        solve_zooms(few, Options())


def test_geometry_driven_zoom_keeps_the_robots_size_with_the_measured_lens() -> None:
    """A 500 mm robot asked to fill 30 % of the picture's height anywhere in the crater (2.5–6
    m from the camera): within 10 % through the measured curve; the straight line misses."""
    from services.ptz.aim import zoom_for_size

    rng = np.random.default_rng(21)
    truth = drawn_lens(rng)
    fit, _ = solve_zooms(as_passpoints(zoom_passpoints(PAPER_POSE, truth, ZOOMS, rng, 60)),
                         Options())
    worst = {"measured": 0.0, "straight line": 0.0}
    for distance in np.linspace(2500.0, 6000.0, 30):
        for name, lens in (("measured", fit.lens()), ("straight line", PtzLens())):
            zoom = zoom_for_size(distance, object_mm=500.0, image_fraction=0.3, lens=lens)
            seen = 500.0 * truth.intrinsics(zoom).fz_px / distance / 576  # of its height
            worst[name] = max(worst[name], abs(seen / 0.3 - 1))
    assert worst["measured"] <= 0.10, worst
    assert worst["straight line"] > 0.25, worst
