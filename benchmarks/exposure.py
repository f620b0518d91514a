"""The tracking camera's exposure and the marker detector: what each exposure does to the
pictures the gantry sees and to how well the crane follows.

    .venv/bin/python -m benchmarks.exposure [--exposures-ms 0.5,1,2,4,8,16] [--seeds 1,2]

Each exposure runs ``stb experiment gantry``'s loop (``default``) on the locomotive and the
walker with the sim's tracking camera at that exposure (``[sim.tracking_camera] exposure_s``:
the picture that much brighter below saturation, a moving marker smeared that much longer;
the sim's levels per ms: docs/sim.md). Every picture the gantry looks at is checked against
the sim's truth: the robot's marker found (a spot within 2 px of where the sim drew it), how
many other spots came with it (reflections taken for markers), and the spot's distance from
the truth. The paper lowered the exposure "to obtain just the specific image information"
(§3.1); this measures how far.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any
from unittest import mock

import numpy as np

import services.gantry.control as control
from common.lab_paths import SIM_CRATER_FILE
from common.markers import detect
from services.args import Parser
from services.experiment import gantry as experiment
from services.gantry.settings import GantrySettings
from services.sim.lab import Lab
from services.sim.robots import MARKER_HEIGHT_MM
from services.sim.settings import SimSettings


def one(scenario: str, seed: int, exposure_ms: float, crater: Path) -> dict[str, Any]:
    """One run at one exposure: the loop's rms and what the detector made of each picture."""
    truth: list[np.ndarray] = []  # the marker's true pixel in the picture drawn last
    seen: list[tuple[bool, int, float]] = []  # (found, other spots, distance px)
    lab_ref: list[Lab] = []
    render = Lab.tracking_frame

    def drawn(self: Lab, t: float, rng: np.random.Generator) -> np.ndarray:
        lab_ref[:] = [self]
        pixel = self.tracking.project(self.robot(t)[None, :], self.crane_world_at(t),
                                      self.crane_frame)[0][0]
        truth.append(np.asarray(pixel))
        return render(self, t, rng)

    def found(image: np.ndarray, **kwargs: Any) -> Any:
        result = detect(image, **kwargs)
        if truth:
            u, v = truth[-1]
            distances = sorted(float(np.hypot(s.u - u, s.v - v)) for s in result.markers)
            hit = bool(distances) and distances[0] <= 2.0
            seen.append((hit, len(distances) - (1 if hit else 0),
                         distances[0] if hit else float("nan")))
        return result

    sim = SimSettings()
    sim = sim.model_copy(update={"tracking_camera": sim.tracking_camera.model_copy(
        update={"exposure_s": exposure_ms / 1000.0})})
    settings = experiment.gantry_for(GantrySettings(), "default", seed=seed,
                                     marker_height_mm=MARKER_HEIGHT_MM[scenario])
    with mock.patch.object(Lab, "tracking_frame", drawn), \
            mock.patch.object(control, "detect", found):
        run = experiment.run(experiment.make_lab(scenario, seed, crater, sim), settings)
    hits = np.array([h for h, _, _ in seen])
    others = np.array([n for _, n, _ in seen])
    off = np.array([d for h, _, d in seen if h])
    summary = run.summary()
    return {"scenario": scenario, "seed": seed, "exposure_ms": exposure_ms,
            "pictures": len(seen), "found_pct": round(100 * float(hits.mean()), 2),
            "other_spots_per_picture": round(float(others.mean()), 3),
            "off_px_median": round(float(np.median(off)), 3) if len(off) else None,
            "off_px_p99": round(float(np.percentile(off, 99)), 3) if len(off) else None,
            "rms_mm": summary["rms_mm"], "held_ticks": summary["held_ticks"]}


def main() -> None:
    parser = Parser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--exposures-ms", default="0.5,1,2,4,8,16")
    parser.add_argument("--scenarios", default="locomotive,walker")
    parser.add_argument("--seeds", default="1,2")
    parser.add_argument("--crater", type=Path, default=SIM_CRATER_FILE)
    args = parser.parse_args()
    rows = []
    say: Callable[[dict], None] = lambda r: print(  # noqa: E731
        f"  {r['scenario']:<10} seed {r['seed']} {r['exposure_ms']:5.2f} ms: found "
        f"{r['found_pct']:6.2f} %, other spots {r['other_spots_per_picture']:.3f}/picture, "
        f"off {r['off_px_median']} px (p99 {r['off_px_p99']}), rms {r['rms_mm']} mm, "
        f"held {r['held_ticks']}", flush=True)
    for scenario in args.scenarios.split(","):
        for exposure in [float(e) for e in args.exposures_ms.split(",")]:
            for seed in [int(s) for s in args.seeds.split(",")]:
                rows.append(one(scenario, seed, exposure, args.crater))
                say(rows[-1])
    print(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
