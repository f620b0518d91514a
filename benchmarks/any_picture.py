"""The multi-zoom fit on cameras of any picture: synthetic collections of drawn cameras.

    .venv/bin/python -m benchmarks.any_picture [--cameras 24] [--seed 100]

Each camera is drawn as ``tests/calib/test_zoom_fit.py`` draws it (its picture among 1280 × 720,
1920 × 1080, 2560 × 1440, 3840 × 2160 and PAL 704 × 576, its chip, zoom range, distortion and
principal point: ``drawn_camera``), seen at the recommended zoom steps with 100 passpoints a
step and 0.3 px of noise in a 704-wide picture (scaled), and fitted as the calibration service
does (``Options.in_picture``). Prints per camera and the largest and median of: the focal
length's error at the worst step, the distortion's in the picture but its edge band and at its
very edge, and the principal point's (pixels of a 704-wide picture: the same angles), and the
pose's error.
"""

from __future__ import annotations

import argparse

import numpy as np

from common.camera import pose_distance
from services.calib.solve import Options
from services.calib.synthetic import PAPER_POSE, zoom_passpoints
from services.calib.zoom_fit import solve_zooms
from tests.calib.test_zoom_fit import (
    EDGE_BAND,
    PICTURES,
    STEPS,
    ZOOMS,
    as_passpoints,
    distortion_error_px,
    drawn_camera,
    sim_camera,
)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cameras", type=int, default=24)
    parser.add_argument("--seed", type=int, default=100)
    args = parser.parse_args()
    rows = []
    print("| seed | picture | focal, worst step | distortion, edge band / very edge | "
          "principal point | pose |")
    print("|---|---|---:|---:|---:|---:|")
    for seed in range(args.seed, args.seed + args.cameras):
        rng = np.random.default_rng(seed)
        picture = PICTURES[int(rng.integers(len(PICTURES)))]
        truth = sim_camera(drawn_camera(rng, picture)).lens()
        scale = picture[0] / 704
        sets = zoom_passpoints(PAPER_POSE, truth, ZOOMS, rng, count=100, noise_px=0.3 * scale)
        fit, _ = solve_zooms(as_passpoints(sets), Options.in_picture(picture))
        lens, wide = fit.lens(), truth.intrinsics(1)
        focal = 100 * max(abs(lens.focal_px(z) / truth.focal_px(z) - 1) for z in STEPS)
        band = distortion_error_px(lens.intrinsics(1), wide, EDGE_BAND) / scale
        edge = distortion_error_px(lens.intrinsics(1), wide) / scale
        assert fit.principal_px is not None
        principal = float(np.hypot(fit.principal_px[0] - wide.cy_px,
                                   fit.principal_px[1] - wide.cz_px)) / scale
        position, angle = pose_distance(fit.pose, PAPER_POSE)
        rows.append((focal, band, edge, principal, position, angle))
        print(f"| {seed} | {picture[0]}×{picture[1]} | {focal:.2f} % | {band:.2f} / {edge:.2f} px "
              f"| {principal:.2f} px | {position:.2f} mm / {angle:.3f}° |", flush=True)
    table = np.array(rows)
    for name, values in (("largest", table.max(axis=0)), ("median", np.median(table, axis=0))):
        print(f"{name}: focal {values[0]:.2f} %, distortion {values[1]:.2f} / {values[2]:.2f} px, "
              f"principal point {values[3]:.2f} px, pose {values[4]:.2f} mm / {values[5]:.3f}°")


if __name__ == "__main__":
    main()
