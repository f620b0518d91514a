"""``stb experiment``: the paper's gantry experiments (§3.3) on a simulated clock.

    stb experiment gantry [--scenario locomotive|walker] [--trajectory FILE.csv |
        --recording RUN.mcap] [--algorithm NAME|all] [--seed N] [--lab FILE] [--plot DIR] [--json]
    stb experiment identify [--seeds 1-5] [--evaluations N] [--lab FILE] [--json]

``gantry`` runs the gantry's own controller with the lab's gantry settings (``--lab``, else
the defaults) against the simulated crane and tracking camera, and prints per algorithm the
crane-to-robot error: std x / y (the paper's Tables 3 and 4), rms and max, and how much faster
than real time it ran. ``identify`` fits the simulated crane and robots so that the paper's
three algorithms reproduce those tables (docs/experiments.md).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, TextIO

from common.errors import ConfigError
from common.lab_paths import SIM_CRATER_FILE
from common.names import ALGORITHMS
from services.args import Parser, plain
from services.experiment.paper import TABLES
from services.sim.scenarios import FOLLOWED

if TYPE_CHECKING:  # imported once the flags are parsed: --help answers at once
    from services.gantry.settings import GantrySettings
    from services.sim.settings import SimSettings

PROG = "stb experiment"
EXIT_USAGE = 2


def main(argv: Sequence[str] | None = None) -> int:
    parser = _parser()
    args = parser.parse_args(sys.argv[1:] if argv is None else list(argv))
    if args.command is None:
        parser.print_help()
        return EXIT_USAGE
    from common.settings import load_settings
    from services.gantry.settings import GantrySettings
    from services.sim.settings import SimSettings

    try:
        gantry = load_settings(GantrySettings, args.lab)
        sim = load_settings(SimSettings, args.lab)
    except ConfigError as err:
        print(f"{PROG}: {err}", file=sys.stderr)
        return EXIT_USAGE
    if args.command == "identify":
        from services.experiment.identify_cli import identify

        return identify(args, gantry, sim)
    return _gantry(args, gantry, sim)


def _parser() -> argparse.ArgumentParser:
    parser = Parser(prog=PROG, description=plain(__doc__ or ""),
                    formatter_class=argparse.RawDescriptionHelpFormatter)
    commands = parser.add_subparsers(dest="command", metavar="gantry|identify")
    g = commands.add_parser("gantry", help="the gantry experiments: Tables 3 and 4",
                            description="Run the paper's gantry experiment on a simulated clock.")
    g.add_argument("--scenario", choices=FOLLOWED, default="locomotive",
                   help="the paper's locomotive or walker, or one of our paths (docs/sim.md)")
    path = g.add_mutually_exclusive_group()
    path.add_argument("--trajectory", type=Path, metavar="FILE.csv",
                      help="a robot path instead of the scenario's: CSV t,x,y (s, mm)")
    path.add_argument("--recording", type=Path, metavar="RUN.mcap",
                      help="the robot's path from a recording (stb record): the sim's truth "
                      "if recorded, else the tracker's robot position")
    g.add_argument("--algorithm", choices=[*ALGORITHMS, "all", "oracle"], default="all",
                   help="oracle: not an algorithm but the bound — the robot's true path "
                   "--ahead seconds after each frame (no causal predictor can beat it)")
    g.add_argument("--ahead", type=float, nargs="+", default=[0.2, 0.3, 0.4, 0.5, 0.6, 0.8],
                   metavar="S", help="the oracle's look-ahead(s) (default: a sweep)")
    g.add_argument("--seed", type=int, default=1)
    g.add_argument("--gantry-map", type=Path, metavar="FILE.npz",
                   help="the gantry's height map where it is not the sim's crater (a laser "
                   "scan imported with stb crater import)")
    g.add_argument("--plot", type=Path, metavar="DIR", help="error-over-time plots")
    g.add_argument("--json", action="store_true", help="one JSON document on stdout")
    i = commands.add_parser("identify", help="fit the sim to the paper's Tables 3 and 4",
                            description="Identify the simulated crane and robots against the "
                            "paper's Tables 3 and 4 (docs/experiments.md).")
    i.add_argument("--seeds", default="1-5", help="seeds averaged per evaluation (1-5)")
    i.add_argument("--evaluations", type=int, default=0, metavar="N",
                   help="fit with at most N evaluations (0: only evaluate the current values)")
    i.add_argument("--start", type=Path, metavar="FIT.json",
                   help="start from the parameters of an earlier fit")
    i.add_argument("--out", type=Path, metavar="FIT.json", help="write the fit here")
    i.add_argument("--workers", type=int, default=2, help="processes (default 2)")
    i.add_argument("--json", action="store_true")
    for sub in (g, i):
        sub.add_argument("--lab", type=Path, metavar="FILE",
                         help="the lab file: its [gantry] and [sim] settings (else defaults)")
        sub.add_argument("--crater", type=Path, default=SIM_CRATER_FILE,
                         help="height map (made from the sim's default seed if missing)")
    return parser


def _gantry(args: argparse.Namespace, gantry: GantrySettings, sim: SimSettings) -> int:
    from services.experiment.gantry import run_scenario
    from services.experiment.paths import check_workspace, read_csv, read_recording

    try:
        path = (read_csv(args.trajectory) if args.trajectory else
                read_recording(args.recording) if args.recording else None)
        if path is not None:
            check_workspace(path, args.trajectory or args.recording,
                            (gantry.x_min_mm, gantry.x_max_mm), (gantry.y_min_mm, gantry.y_max_mm))
    except ValueError as err:
        print(f"{PROG} gantry: {err}", file=sys.stderr)
        return EXIT_USAGE
    oracle = args.algorithm == "oracle"
    names = ALGORITHMS if args.algorithm == "all" else ("default",) * len(args.ahead) \
        if oracle else (args.algorithm,)
    runs = []
    progress = Progress(len(names), sys.stderr) if not args.json and sys.stderr.isatty() \
        else None
    for i, name in enumerate(names):
        label = f"oracle {args.ahead[i]:.2f} s" if oracle else name
        runs.append(run_scenario(args.scenario, name, seed=args.seed, crater_file=args.crater,
                                 gantry=gantry, sim=sim, path=path,
                                 oracle_ahead_s=args.ahead[i] if oracle else None,
                                 gantry_map=args.gantry_map,
                                 progress=progress.runner(label) if progress else None))
        if progress:
            progress.clear()
        if not args.json:
            print(_line(runs[-1].summary(), None if path else args.scenario), flush=True)
    if args.plot:
        from services.experiment.plots import write_plots

        for written in write_plots(runs, args.scenario, args.plot):
            print(f"wrote {written}", file=sys.stderr if args.json else sys.stdout)
    if args.json:
        print(json.dumps({"scenario": args.scenario, "seed": args.seed,
                          "path": str(args.trajectory or args.recording or ""),
                          "results": [r.summary() for r in runs]}))
    return 0


class Progress:
    """One line on a terminal, rewritten as the runs go: which run, how far, the time left for
    it and for all (from the runs' pace so far)."""

    def __init__(self, runs: int, out: TextIO,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.runs, self.out, self.clock = runs, out, clock
        self.started, self.done = clock(), 0

    def runner(self, label: str) -> Callable[[float], None]:
        run_started = self.clock()

        def show(share: float) -> None:
            now = self.clock()
            left = "" if share < 0.02 else (
                f", about {(now - run_started) * (1 - share) / share:.0f} s left")
            if self.done and share >= 0.02:
                per_run = (now - self.started) / (self.done + share)
                left += f", about {per_run * (self.runs - self.done - share):.0f} s for all"
            self.out.write(f"\r\033[K{label} ({self.done + 1} of {self.runs}): "
                           f"{100 * share:.0f} %{left}")
            self.out.flush()
        return show

    def clear(self) -> None:
        self.done += 1
        self.out.write("\r\033[K")
        self.out.flush()


def _line(s: dict, scenario: str | None) -> str:
    paper = TABLES.get(scenario or "", {}).get(s["algorithm"])
    return (f"{s['algorithm']:<18} std x {s['std_x_mm']:7.1f}  y {s['std_y_mm']:7.1f}  rms "
            f"{s['rms_mm']:7.1f}  max {s['max_mm']:7.1f} mm   ({s['speedup']:.0f}× real time)"
            + (f"   paper: {paper[0]} / {paper[1]} mm" if paper else ""))
