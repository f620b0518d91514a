"""Planning a zoom collection: which zoom steps, and how many passpoints in the picture's
corners at the widest step, on lenses drawn at random (no sim, no services: the pure fit).

    .venv/bin/python -m benchmarks.zoom_plan [--lenses 200] [--draws 30] [--seed 12]

* **Steps**: the focal length between the measured steps is interpolated (PCHIP), so even a
  perfect measurement at each step leaves an error between them. For each step list, the
  largest error anywhere 1–9999 of a curve through the *true* focal lengths at those steps,
  over ``--lenses`` lenses drawn as ``tests/calib/test_zoom_fit.drawn_lens`` does (seeds 0, 1,
  …), and over as many others (seeds from 1000: the recommended steps were chosen on a grid
  against the first 60 lenses, these say whether that choice holds for lenses it never saw).
* **Corners**: the distortion is largest in the corners; a fit with no passpoints there
  extrapolates. For one drawn lens (``--seed``), ``--draws`` synthetic collections (170
  passpoints at zoom 1 anywhere but the corners, plus so many in each corner — 15 % of the
  picture's width and height from its edges —, 90 anywhere at every other step, 0.35 px
  noise per axis, as the sim's collections' zoom-1 residuals show): the largest difference
  anywhere in the wide picture between the fitted and the true distortion.
* **Passpoints at the other steps**: collections with 3 per corner and 90, 45, 30 or 20
  passpoints at each step but the widest (the widest step's passpoints the same in each row):
  the focal length's largest error 1–9999 and the distortion's (``calib.step_count``).
"""

from __future__ import annotations

import argparse

import numpy as np

from common.camera import Pose
from common.passpoint_collector import corner_of
from common.passpoints import Passpoints
from common.ptz_lens import PtzLens, ZoomCurve
from services.calib.solve import Options
from services.calib.synthetic import PAPER_POSE, seen_at
from services.calib.zoom_fit import solve_zooms
from tests.calib.test_zoom_fit import EDGE_BAND, STEPS, ZOOMS, distortion_error_px, drawn_lens

SEVEN = [1, 3000, 5500, 7000, 8000, 9000, 9999]
EIGHT_BEFORE = [1, 1500, 3000, 5500, 7000, 8000, 9000, 9999]  # ZOOMS until 2026-12-07
OTHER_LENSES = 1000  # the seeds of lenses not among those the steps were chosen on
WIDTH_PX, HEIGHT_PX = 704, 576
CORNER_SHARE = 0.15
NOISE_PX = 0.35


def interpolation_error(lens: PtzLens, zooms: list[int]) -> float:
    """The largest relative focal-length error 1–9999 of the curve through the true focal
    lengths at ``zooms``."""
    through = ZoomCurve(tuple(float(z) for z in zooms), tuple(lens.focal_px(z) for z in zooms))
    return max(abs(through.focal(z) / lens.focal_px(z) - 1) for z in STEPS)


def _wide_pixels(rng: np.random.Generator, per_corner: int, anywhere_else: int = 170
                 ) -> np.ndarray:
    inside: list[tuple[float, float]] = []
    while len(inside) < anywhere_else:
        u, v = rng.uniform(10, WIDTH_PX - 10), rng.uniform(10, HEIGHT_PX - 10)
        if corner_of(u, v, WIDTH_PX, HEIGHT_PX, CORNER_SHARE) is None:
            inside.append((u, v))
    corner_u, corner_v = CORNER_SHARE * WIDTH_PX, CORNER_SHARE * HEIGHT_PX
    corners = []
    for right in (False, True):
        for bottom in (False, True):
            us = rng.uniform(7, corner_u, per_corner)
            vs = rng.uniform(7, corner_v, per_corner)
            corners.append(np.column_stack([WIDTH_PX - us if right else us,
                                            HEIGHT_PX - vs if bottom else vs]))
    return np.concatenate([np.array(inside), *corners])


def collection(pose: Pose, lens: PtzLens, rng: np.random.Generator, per_corner: int,
               per_step: int = 90, steps_rng: np.random.Generator | None = None
               ) -> dict[int, Passpoints]:
    """Passpoints at every zoom (``steps_rng``, if given, draws those of the steps but the
    widest: the same widest step with different others)."""
    by_zoom = {}
    for zoom in ZOOMS:
        intr = lens.intrinsics(zoom)
        draw = rng if zoom == ZOOMS[0] or steps_rng is None else steps_rng
        seen = (_wide_pixels(draw, per_corner) if zoom == ZOOMS[0] else
                draw.uniform([1, 1], [WIDTH_PX - 1, HEIGHT_PX - 1], (per_step, 2)))
        at = seen_at(pose, intr, seen, draw, NOISE_PX)
        by_zoom[zoom] = Passpoints(at.world_mm, at.pixels)
    return by_zoom


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="benchmarks.zoom_plan", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--lenses", type=int, default=200)
    parser.add_argument("--draws", type=int, default=30)
    parser.add_argument("--seed", type=int, default=12)
    args = parser.parse_args(argv)
    lenses = [drawn_lens(np.random.default_rng(s)) for s in range(args.lenses)]
    print(f"focal length between the steps, interpolation alone, {args.lenses} drawn lenses:")
    others = [drawn_lens(np.random.default_rng(OTHER_LENSES + s)) for s in range(args.lenses)]
    print("| steps | median | 95th percentile | largest | other lenses: median | largest |"
          "\n|---|---:|---:|---:|---:|---:|")
    for zooms in (SEVEN, EIGHT_BEFORE, ZOOMS):
        errors = 100 * np.array([interpolation_error(lens, zooms) for lens in lenses])
        unseen = 100 * np.array([interpolation_error(lens, zooms) for lens in others])
        print(f"| {','.join(map(str, zooms))} | {np.median(errors):.2f} % | "
              f"{np.percentile(errors, 95):.2f} % | {errors.max():.2f} % | "
              f"{np.median(unseen):.2f} % | {unseen.max():.2f} % |", flush=True)
    truth = drawn_lens(np.random.default_rng(args.seed))
    print(f"\ndistortion at zoom 1, lens of seed {args.seed}, {args.draws} collections each:")
    print(f"| passpoints per corner | median | 90th percentile | largest | without the "
          f"{100 * EDGE_BAND:.0f} % edge band: median | largest |\n|---:|---:|---:|---:|---:|---:|")
    for per_corner in (0, 1, 3, 6):
        corner_errors: list[float] = []
        covered: list[float] = []
        for draw in range(args.draws):
            rng = np.random.default_rng((args.seed, per_corner, draw))
            fit, _ = solve_zooms(collection(PAPER_POSE, truth, rng, per_corner), Options())
            wide, true_wide = fit.lens().intrinsics(1), truth.intrinsics(1)
            corner_errors.append(distortion_error_px(wide, true_wide))
            covered.append(distortion_error_px(wide, true_wide, inset=EDGE_BAND))
        print(f"| {per_corner} | {np.median(corner_errors):.2f} px | "
              f"{np.percentile(corner_errors, 90):.2f} px | {max(corner_errors):.2f} px | "
              f"{np.median(covered):.2f} px | {max(covered):.2f} px |", flush=True)
    print(f"\npasspoints at each step but the widest (3 per corner there), lens of seed "
          f"{args.seed}, {args.draws} collections each:")
    print("| per step | focal, worst step: median | largest | distortion: median | largest |"
          "\n|---:|---:|---:|---:|---:|")
    for per_step in (90, 45, 30, 20):
        focal, bend = [], []
        for draw in range(args.draws):
            rng = np.random.default_rng((args.seed, 100, draw))  # the same widest step
            steps_rng = np.random.default_rng((args.seed, 100 + per_step, draw))
            fit, _ = solve_zooms(collection(PAPER_POSE, truth, rng, 3, per_step, steps_rng),
                                 Options())
            lens = fit.lens()
            focal.append(100 * max(abs(lens.focal_px(z) / truth.focal_px(z) - 1)
                                   for z in STEPS))
            bend.append(distortion_error_px(lens.intrinsics(1), truth.intrinsics(1)))
        print(f"| {per_step} | {np.median(focal):.2f} % | {max(focal):.2f} % | "
              f"{np.median(bend):.2f} px | {max(bend):.2f} px |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
