"""Marker detection speed: ``common.markers.detect`` against OpenCV on one synthetic frame set.

    .venv/bin/python -m benchmarks.markers [--frames 200] [--rounds 5]

Every frame is 704×576 (the AXIS 215's resolution), made from a fixed seed; one set per
kind: the mixed set (1–3 IR markers of radius 2–15 px with soft edges, 0–3 elongated
reflections, sensor noise), and the light frames of a dark crater: empty, sensor noise only,
one marker, three markers, one stray reflection (each with noise but the empty one). Each
method runs on every frame of the set in turn, the methods' order rotating every round (so drift
of the shared
machine hits them alike), OpenCV limited to one thread:

* ``detect``: ours (threshold 230, up to 5 markers);
* ``cv findContours``: threshold + findContours + moments of every contour;
* ``cv connectedComponents``: threshold + connectedComponentsWithStats;
* ``numpy floor``: one plain numpy pass over the frame (count pixels ≥ 230).

Prints median and p99 per frame in µs and each method's ratio to the findContours route.
"""

from __future__ import annotations

import argparse
import json
import platform
import time

import cv2
import numpy as np

from common.markers import detect
from services.args import Parser

THRESHOLD = 230


def make_frames(count: int, seed: int = 7, markers: tuple[int, int] = (1, 4),
                reflections: tuple[int, int] = (0, 4), noise: float = 2.5) -> list[np.ndarray]:
    """``count`` frames with ``markers`` and ``reflections`` drawn from [lo, hi) each."""
    rng = np.random.default_rng(seed)
    rows, cols = np.mgrid[0:576, 0:704]
    frames = []
    for _ in range(count):
        image = np.full((576, 704), 16.0)
        for _ in range(rng.integers(*markers)):
            u, v, r = rng.uniform(20, 684), rng.uniform(20, 556), rng.uniform(2, 15)
            coverage = np.clip(r - np.hypot(cols - u, rows - v) + 0.5, 0, 1)
            image = np.maximum(image, 16 + coverage * 239)
        for _ in range(rng.integers(*reflections)):
            streak = np.zeros((576, 704), np.uint8)
            cv2.ellipse(streak, ((rng.uniform(0, 704), rng.uniform(0, 576)),
                                 (rng.uniform(10, 40), rng.uniform(2, 6)), rng.uniform(0, 180)),
                        235, -1, cv2.LINE_AA)
            image = np.maximum(image, streak)
        image = cv2.GaussianBlur(image, (0, 0), 0.7) + rng.normal(0, noise, image.shape)
        frames.append(np.clip(np.rint(image), 0, 255).astype(np.uint8))
    return frames


def ours(frame: np.ndarray) -> object:
    return detect(frame, threshold=THRESHOLD, max_markers=5)


def cv_contours(frame: np.ndarray) -> object:
    _, binary = cv2.threshold(frame, THRESHOLD - 1, 255, cv2.THRESH_BINARY)
    contours, _ = cv2.findContours(binary, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    return [cv2.moments(c) for c in contours]


def cv_components(frame: np.ndarray) -> object:
    _, binary = cv2.threshold(frame, THRESHOLD - 1, 255, cv2.THRESH_BINARY)
    return cv2.connectedComponentsWithStats(binary, connectivity=4)


def numpy_floor(frame: np.ndarray) -> object:
    return np.count_nonzero(frame >= THRESHOLD)


METHODS = {"detect": ours, "cv findContours": cv_contours,
           "cv connectedComponents": cv_components, "numpy floor": numpy_floor}


def run(frames: list[np.ndarray], rounds: int) -> dict[str, dict[str, float]]:
    cv2.setNumThreads(1)
    for method in METHODS.values():  # warm-up (and the detector's one-time compilation)
        method(frames[0])
    times: dict[str, list[int]] = {name: [] for name in METHODS}
    names = list(METHODS)
    for r in range(rounds):
        # Each method over the whole set, as a camera service runs it; the order rotates
        # every round so that drift of the shared machine hits every method alike.
        for name in names[r % len(names):] + names[: r % len(names)]:
            method = METHODS[name]
            for frame in frames:
                start = time.perf_counter_ns()
                method(frame)
                times[name].append(time.perf_counter_ns() - start)
    reference = np.median(times["cv findContours"])
    return {name: {"median_us": float(np.median(t)) / 1e3,
                   "p99_us": float(np.percentile(t, 99)) / 1e3,
                   "ratio_to_findContours": float(np.median(t) / reference)}
            for name, t in times.items()}


SETS = {  # name: (markers, reflections, noise) — the light frames are the common case
    "mixed (1-3 markers, 0-3 reflections)": ((1, 4), (0, 4), 2.5),
    "empty": ((0, 1), (0, 1), 0.0),
    "noise only": ((0, 1), (0, 1), 2.5),
    "1 marker": ((1, 2), (0, 1), 2.5),
    "3 markers": ((3, 4), (0, 1), 2.5),
    "1 reflection": ((0, 1), (1, 2), 2.5),
}


def main() -> None:
    parser = Parser(description=__doc__,
                    formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=200)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    results = {name: run(make_frames(args.frames, markers=m, reflections=r, noise=n),
                         args.rounds) for name, (m, r, n) in SETS.items()}
    if args.json:
        print(json.dumps(results, indent=2))
        return
    print(f"{args.frames} frames × {args.rounds} rounds per set, 704×576, OpenCV "
          f"{cv2.__version__} (1 thread), numpy {np.__version__}, "
          f"{platform.processor() or platform.machine()}")
    print("| set | method | median µs | p99 µs | median / findContours |")
    print("|---|---|---|---|---|")
    for set_name, per_method in results.items():
        for name, r in per_method.items():
            print(f"| {set_name} | {name} | {r['median_us']:.1f} | {r['p99_us']:.1f} | "
                  f"{r['ratio_to_findContours']:.2f} |")


if __name__ == "__main__":
    main()
