"""The gantry's algorithms on every path the sim has, seeds 1–10: the tables of
docs/experiments.md §2.

    .venv/bin/python -m benchmarks.gantry_table [--paths locomotive,walker,...] [--seeds 1-10]
        [--algorithms basic,pf-position,pf-velocity,default] [--workers 2] [--json FILE]
        [--lab FILE]

Each run is ``stb experiment gantry --scenario PATH --algorithm NAME --seed N`` (the same
``run_scenario``), on ``--workers`` processes. Prints per path the mean std x / y and the rms
range of each algorithm, then per seed ``default``'s rms against the best of the paper's three
(basic, pf-position, pf-velocity) in the same run, their ratio, and the worst seed.
"""

from __future__ import annotations

import argparse
import json
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from services.args import Parser
from services.sim.scenarios import FOLLOWED

PAPER = ("basic", "pf-position", "pf-velocity")


def one(job: tuple[str, str, int, str | None]) -> dict:
    from common.lab_paths import SIM_CRATER_FILE
    from common.settings import load_settings
    from services.experiment.gantry import run_scenario
    from services.gantry.settings import GantrySettings
    from services.sim.settings import SimSettings

    path, algorithm, seed, lab = job
    lab_file = Path(lab) if lab else None
    gantry, sim = load_settings(GantrySettings, lab_file), load_settings(SimSettings, lab_file)
    summary = run_scenario(path, algorithm, seed=seed, crater_file=SIM_CRATER_FILE,  # type: ignore[arg-type]
                           gantry=gantry, sim=sim).summary()
    return {"path": path, "seed": seed, **summary}


def seeds_of(text: str) -> list[int]:
    low, _, high = text.partition("-")
    return list(range(int(low), int(high or low) + 1))


def tables(rows: list[dict], algorithms: list[str]) -> str:
    out = []
    for path in dict.fromkeys(r["path"] for r in rows):
        mine = [r for r in rows if r["path"] == path]
        out += [f"\n{path}", "| algorithm | std x / y mm (mean) | rms mm (range) |",
                "|---|---|---|"]
        for name in algorithms:
            runs = [r for r in mine if r["algorithm"] == name]
            if runs:
                rms = [r["rms_mm"] for r in runs]
                out.append(f"| {name} | {np.mean([r['std_x_mm'] for r in runs]):.1f} / "
                           f"{np.mean([r['std_y_mm'] for r in runs]):.1f} | "
                           f"{min(rms):.1f}–{max(rms):.1f} |")
        ratios = _ratios(mine)
        if ratios:
            out.append("| seed | " + " | ".join(str(s) for s in ratios) + " |")
            out.append("|---|" + "---|" * len(ratios))
            out.append("| default / paper's best rms | " + " | ".join(
                f"{d:.1f} / {b:.1f}" for d, b, _ in ratios.values()) + " |")
            out.append("| ratio | " + " | ".join(f"{r:.2f}" for *_, r in ratios.values()) + " |")
            worst = max(ratios, key=lambda s: ratios[s][2])
            out.append(f"worst seed {worst}: {ratios[worst][2]:.2f}; mean "
                       f"{np.mean([r for *_, r in ratios.values()]):.2f}")
    return "\n".join(out)


def _ratios(rows: list[dict]) -> dict[int, tuple[float, float, float]]:
    """Per seed: default's rms, the best of the paper's three's, their ratio."""
    out = {}
    for seed in sorted({r["seed"] for r in rows}):
        by = {r["algorithm"]: r["rms_mm"] for r in rows if r["seed"] == seed}
        paper = [by[a] for a in PAPER if a in by]
        if "default" in by and paper:
            out[seed] = (by["default"], min(paper), by["default"] / min(paper))
    return out


def main(argv: list[str] | None = None) -> int:
    parser = Parser(prog="python -m benchmarks.gantry_table", description=__doc__.split("\n\n")[0],
                    formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--paths", default=",".join(FOLLOWED))
    parser.add_argument("--seeds", default="1-10")
    parser.add_argument("--algorithms", default=",".join((*PAPER, "default")))
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--lab", type=Path, help="the lab file's [gantry] and [sim]")
    parser.add_argument("--json", type=Path, help="write every run's summary here")
    args = parser.parse_args(argv)
    algorithms = args.algorithms.split(",")
    jobs = [(p, a, s, str(args.lab) if args.lab else None) for p in args.paths.split(",")
            for s in seeds_of(args.seeds) for a in algorithms]
    rows = []
    with ProcessPoolExecutor(args.workers) as pool:
        for i, row in enumerate(pool.map(one, jobs), 1):
            rows.append(row)
            print(f"\r{i}/{len(jobs)} {row['path']} seed {row['seed']} {row['algorithm']}: "
                  f"rms {row['rms_mm']:.1f} mm ({row['speedup']:.0f}×)",
                  end="", file=sys.stderr, flush=True)
    print(file=sys.stderr)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    print(tables(rows, algorithms))
    return 0


if __name__ == "__main__":
    sys.exit(main())
