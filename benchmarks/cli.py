"""The ``stb`` command as a user starts it: ``--help`` of every command, and ``stb calib
solve`` from a cold start.

    .venv/bin/python -m benchmarks.cli [--runs 5]

Each figure is the wall time of a fresh process (``.venv/bin/stb …``), the median and the
slowest of ``--runs``; the reference in the same run is a bare ``python -c pass`` (the
interpreter's own start). ``stb calib solve`` runs on the paper's setup (100 synthetic
passpoints, 2 px noise, services/calib/synthetic.py) with ``--json``: its wall time from a
cold start, and the ``seconds`` it reports (the solve alone: the method's imports are done
before the clock starts), for ``auto`` and for the paper's ``cmaes`` from its guess.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from common.passpoints import write_passpoints
from services.args import Parser
from services.calib.synthetic import PAPER_GUESS, PAPER_POSE, passpoints
from tests.services.test_help_is_light import COMMANDS

ROOT = Path(__file__).resolve().parents[1]
STB = ROOT / ".venv" / "bin" / "stb"


def _wall(command: list[str], runs: int) -> tuple[float, float, str]:
    """(median s, max s, the last stdout) of ``runs`` fresh processes."""
    times, out = [], ""
    for _ in range(runs):
        started = time.perf_counter()
        done = subprocess.run(command, capture_output=True, text=True, timeout=120,
                              cwd=ROOT, check=False)
        times.append(time.perf_counter() - started)
        if done.returncode != 0:
            raise SystemExit(f"{' '.join(command)} failed: {done.stderr[-500:]}")
        out = done.stdout
    return float(np.median(times)), max(times), out


def main() -> None:
    parser = Parser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=5)
    args = parser.parse_args()
    median, worst, _ = _wall([sys.executable, "-c", "pass"], args.runs)
    print(f"{'command':<32}{'median s':>10}{'max s':>8}")
    print(f"{'python -c pass (reference)':<32}{median:10.3f}{worst:8.3f}")
    slowest = 0.0
    for command in COMMANDS:
        median, worst, _ = _wall([str(STB), *command, "--help"], args.runs)
        slowest = max(slowest, worst)
        print(f"{'stb ' + ' '.join([*command, '--help']):<32}{median:10.3f}{worst:8.3f}")
    print(f"slowest --help of all: {slowest:.3f} s")
    with tempfile.TemporaryDirectory() as tmp:
        csv = Path(tmp) / "passpoints.csv"
        write_passpoints(csv, passpoints(PAPER_POSE, np.random.default_rng(1))[0])
        guess = ",".join(str(v) for v in (*PAPER_GUESS.position, PAPER_GUESS.rx_deg,
                                          PAPER_GUESS.ry_deg, PAPER_GUESS.rz_deg))
        for method, extra in (("auto", []), ("cmaes", ["--initial", guess])):
            median, worst, out = _wall([str(STB), "calib", "solve", str(csv), "--method",
                                        method, *extra, "--json"], args.runs)
            reported = json.loads(out)["seconds"]
            print(f"{'stb calib solve --method ' + method:<32}{median:10.3f}{worst:8.3f}"
                  f"   reported solve: {1e3 * reported:.1f} ms")


if __name__ == "__main__":
    main()
