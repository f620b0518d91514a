"""``stb experiment gantry``: the paper's gantry experiments (§3.3) on a simulated clock.

    stb experiment gantry --scenario locomotive|walker [--trajectory FILE.csv]
        --algorithm basic|pf-position|pf-position-gauss|pf-velocity|default|all
        [--seed N] [--plot DIR] [--json]

Prints per algorithm the crane-to-robot error: std_x_mm, std_y_mm (the paper's Tables 3 and 4),
rms_mm and max_mm, and how much faster than real time it ran. FILE.csv: header t,x,y (s, mm).
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path

from services.gantry.experiment import run_scenario
from services.gantry.predict import ALGORITHMS

PAPER = {"locomotive": {"basic": (68.0, 62.5), "pf-position": (94.0, 97.1),
                        "pf-velocity": (59.4, 53.2)},
         "walker": {"basic": (46.3, 50.9), "pf-position": (9.41, 13.1),
                    "pf-velocity": (28.0, 30.8)}}


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] != ["gantry"]:
        print("usage: stb experiment gantry --scenario ... (the only experiment so far)",
              file=sys.stderr)
        return 2
    parser = argparse.ArgumentParser(prog="stb experiment gantry", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenario", choices=["locomotive", "walker"], default="locomotive")
    parser.add_argument("--trajectory", type=Path, help="CSV t,x,y instead of the scenario's")
    parser.add_argument("--algorithm", choices=[*ALGORITHMS, "all"], default="all")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--crater", type=Path, default=Path("run/sim/crater.npz"),
                        help="height map (generated from the seed if missing)")
    parser.add_argument("--plot", type=Path, metavar="DIR", help="error-over-time plots")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv[1:])
    names = ALGORITHMS if args.algorithm == "all" else (args.algorithm,)
    runs = []
    for name in names:
        try:
            runs.append(run_scenario(args.scenario, name, seed=args.seed,
                                     crater_file=args.crater, trajectory_csv=args.trajectory))
        except ValueError as err:
            print(f"stb experiment gantry: {err}", file=sys.stderr)
            return 2
        if not args.json:
            s = runs[-1].summary()
            paper = PAPER.get(args.scenario, {}).get(name)
            print(f"{name:<18} std x {s['std_x_mm']:7.1f}  y {s['std_y_mm']:7.1f}  rms "
                  f"{s['rms_mm']:7.1f}  max {s['max_mm']:7.1f} mm   ({s['speedup']:.0f}× real "
                  f"time)" + (f"   paper: {paper[0]} / {paper[1]} mm" if paper else ""),
                  flush=True)
    if args.plot:
        from services.gantry.plots import write_plots

        write_plots(runs, args.scenario, args.plot)
    if args.json:
        print(json.dumps({"scenario": args.scenario, "seed": args.seed,
                          "results": [r.summary() for r in runs]}))
    return 0
