"""Calibration speed and accuracy on the paper's setup (§2.2, Table 2), all methods in one run.

    .venv/bin/python -m benchmarks.calib [--sets 10] [--repeats 5]

The camera of Table 2 (≈ (3413, 1093, 2163) mm, (197, 27, 159)°), 100 passpoints 2–7 m away
all over the image with 2 px noise, a new set per seed. Per set, each method runs
``--repeats`` times (the methods' order rotating) and its median time is kept:

* ``cmaes``: the paper's CMA-ES (pycma, population evaluated at once) from the paper's guess
  (2000, 500, 3000) mm, (180, 0, 180)°;
* ``simplex``: Nelder-Mead (scaled initial simplex) from the same guess;
* ``auto`` (our default): SQPnP inside RANSAC + LM, no guess;
* ``cv solvePnP``: OpenCV's solvePnP (iterative) alone, no guess — the reference;
* ``auto, 10 % wrong``: ours on sets where 10 % of the passpoints are paired wrongly.

Prints per method: median time, evaluations, pose error against the truth (median, max over
the sets), and the time ratio against the paper's figures and against OpenCV.
"""

from __future__ import annotations

import json
import platform
import time
from collections.abc import Callable

import cma
import cv2
import numpy as np

from common.camera import Pose, pose_distance
from common.passpoints import Passpoints
from common.ptz_lens import axis_215
from services.args import Parser
from services.calib.pnp import camera_matrix, pose_from_cv
from services.calib.solve import Options, Solution, solve, warm_up
from services.calib.synthetic import PAPER_GUESS, PAPER_POSE, passpoints

PAPER = {"cmaes": (0.08, 4446), "simplex": (0.04, None)}


def opencv_pnp(points: Passpoints) -> Pose:
    _, rvec, tvec = cv2.solvePnP(points.world_mm, points.pixels, camera_matrix(axis_215(3.8)),
                                 None)
    return pose_from_cv(rvec, tvec)


def methods() -> dict[str, Callable[[Passpoints], tuple[Pose, int]]]:
    def ours(options: Options) -> Callable[[Passpoints], tuple[Pose, int]]:
        def run(points: Passpoints) -> tuple[Pose, int]:
            solution: Solution = solve(points, options)
            return solution.pose, solution.evaluations
        return run

    return {
        "cmaes": ours(Options(method="cmaes", initial=PAPER_GUESS)),
        "simplex": ours(Options(method="simplex", initial=PAPER_GUESS)),
        "auto": ours(Options()),
        "cv solvePnP": lambda points: (opencv_pnp(points), 0),
    }


def main() -> None:
    parser = Parser(description=__doc__)
    parser.add_argument("--sets", type=int, default=10)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    cv2.setNumThreads(1)
    warm_up()
    runs = methods()
    results: dict[str, dict[str, list]] = {name: {"s": [], "evals": [], "mm": [], "deg": []}
                                           for name in [*runs, "auto, 10 % wrong"]}
    for seed in range(args.sets):
        clean, _ = passpoints(PAPER_POSE, np.random.default_rng(seed))
        dirty, _ = passpoints(PAPER_POSE, np.random.default_rng(seed), wrong_fraction=0.1)
        jobs = [(name, fn, clean) for name, fn in runs.items()]
        jobs.append(("auto, 10 % wrong", runs["auto"], dirty))
        times: dict[str, list[float]] = {name: [] for name, _, _ in jobs}
        for repeat in range(args.repeats):
            shift = repeat % len(jobs)
            for name, fn, points in jobs[shift:] + jobs[:shift]:
                started = time.perf_counter()
                pose, evaluations = fn(points)
                times[name].append(time.perf_counter() - started)
                if repeat == args.repeats - 1:  # runs are deterministic: keep the last
                    mm, deg = pose_distance(pose, PAPER_POSE)
                    r = results[name]
                    r["evals"].append(evaluations)
                    r["mm"].append(mm)
                    r["deg"].append(deg)
        for name, values in times.items():
            results[name]["s"].append(float(np.median(values)))
    cv_s = float(np.median(results["cv solvePnP"]["s"]))
    summary = {}
    print(f"{'method':<18} {'median ms':>10} {'evals':>7} {'mm med/max':>12} {'deg max':>8} "
          f"{'/paper':>7} {'/OpenCV':>8}")
    for name, r in results.items():
        s = float(np.median(r["s"]))
        paper = PAPER.get(name, (None, None))[0]
        row = {"median_ms": s * 1e3, "evaluations": int(np.median(r["evals"])),
               "error_mm_median": float(np.median(r["mm"])), "error_mm_max": max(r["mm"]),
               "error_deg_max": max(r["deg"]),
               "ratio_paper": s / paper if paper else None, "ratio_opencv": s / cv_s}
        summary[name] = row
        print(f"{name:<18} {row['median_ms']:>10.3f} {row['evaluations']:>7} "
              f"{row['error_mm_median']:>5.1f}/{row['error_mm_max']:<6.1f} "
              f"{row['error_deg_max']:>8.3f} "
              f"{'' if paper is None else format(s / paper, '.2f'):>7} {s / cv_s:>8.1f}")
    print(json.dumps({"machine": platform.machine(), "python": platform.python_version(),
                      "opencv": cv2.__version__, "cma": cma.__version__, "sets": args.sets,
                      "repeats": args.repeats, "results": summary}))


if __name__ == "__main__":
    main()
