"""Gantry experiment speed: simulated seconds per wall-clock second (at least 50×), and what
one control step costs (at most 1 ms).

    .venv/bin/python -m benchmarks.experiment [--scenarios locomotive,walker] [--seeds 1,2,3]

Runs every algorithm on every scenario and seed, one after the other in this one process (the
first run included: the CLI's first run is a user's first run), on the crater the CLI uses
(``run/sim/crater.npz``, made if missing). Real time is the reference: the ratio is the
speed-up. Prints per algorithm the median and least speed-up and the wall time, and where the
time goes in one walker run (render, detect, the rest), so that a slow-down shows its cause;
and the cost of ``default``'s control step and of each picture it takes in between (the
pictures' drawing by the sim is inside the latter: the experiment draws them when the
controller first looks).
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

import services.gantry.control as control
from common.lab_paths import SIM_CRATER_FILE
from common.names import ALGORITHMS
from services.args import Parser
from services.experiment import gantry as experiment
from services.gantry.settings import GantrySettings
from services.sim.lab import Lab
from services.sim.robots import MARKER_HEIGHT_MM


def speed(scenarios: list[str], seeds: list[int], crater: Path) -> dict[str, dict]:
    runs: dict[str, list[dict]] = {name: [] for name in ALGORITHMS}
    for scenario in scenarios:
        for seed in seeds:
            for name in ALGORITHMS:
                s = experiment.run_scenario(scenario, name, seed=seed, crater_file=crater
                                            ).summary()
                runs[name].append(s)
                print(f"  {scenario:<10} seed {seed}  {name:<18} {s['sim_s']:6.1f} s simulated "
                      f"in {s['wall_s']:5.2f} s  ({s['speedup']:.0f}×)", flush=True)
    return {name: {"runs": len(r),
                   "median_speedup": round(float(np.median([s["speedup"] for s in r])), 1),
                   "least_speedup": round(float(min(s["speedup"] for s in r)), 1),
                   "wall_s": round(float(sum(s["wall_s"] for s in r)), 2)}
            for name, r in runs.items()}


def profile_walker(crater: Path) -> dict[str, float]:
    """Wall time of one default walker run, split into rendering, detection and the rest;
    and what one control step (``Controller.step``, at 4 Hz) and one picture taken in
    between (``Controller.observe``, at 25 Hz) cost: median, 99th percentile, largest (ms)."""
    spent = {"render": 0.0, "detect": 0.0}
    calls: dict[str, list[float]] = {"step": [], "observe": []}

    def timed(what: str, fn: Callable[..., Any]) -> Callable[..., Any]:
        def wrapper(*args: Any, **kwargs: Any) -> Any:
            t = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                if what in calls:
                    calls[what].append(time.perf_counter() - t)
                else:
                    spent[what] += time.perf_counter() - t
        return wrapper

    patched = [(Lab, "tracking_frame", "render"), (control, "detect", "detect"),
               (control.Controller, "step", "step"), (control.Controller, "observe", "observe")]
    originals = [getattr(owner, name) for owner, name, _ in patched]
    for (owner, name, what), original in zip(patched, originals, strict=True):
        setattr(owner, name, timed(what, original))
    settings = experiment.gantry_for(GantrySettings(), "default", seed=1,
                                     marker_height_mm=MARKER_HEIGHT_MM["walker"])
    try:
        r = experiment.run(experiment.make_lab("walker", 1, crater), settings)
    finally:
        for (owner, name, _), original in zip(patched, originals, strict=True):
            setattr(owner, name, original)
    out = {"wall_s": round(r.wall_s, 3), "render_s": round(spent["render"], 3),
           "detect_s": round(spent["detect"], 3),
           "rest_s": round(r.wall_s - spent["render"] - spent["detect"], 3)}
    for what, times in calls.items():  # the pictures are drawn (lazily) inside observe
        ms = np.array(times) * 1e3
        out |= {f"{what}_ms_median": round(float(np.median(ms)), 3),
                f"{what}_ms_p99": round(float(np.percentile(ms, 99)), 3),
                f"{what}_ms_max": round(float(ms.max()), 3), f"{what}_calls": len(ms)}
    return out


def main() -> None:
    parser = Parser(description=__doc__,
                    formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenarios", default="locomotive,walker")
    parser.add_argument("--seeds", default="1,2,3")
    parser.add_argument("--crater", type=Path, default=SIM_CRATER_FILE)
    args = parser.parse_args()
    scenarios = args.scenarios.split(",")
    seeds = [int(s) for s in args.seeds.split(",")]
    print(f"gantry experiment speed on {platform.processor() or platform.machine()}, "
          f"{scenarios} × seeds {seeds}:")
    result = {"per_algorithm": speed(scenarios, seeds, args.crater),
              "walker_default_profile": profile_walker(args.crater)}
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
