"""Do the tests pass on a busy machine? ``make test`` and ``make test-system`` run in a row
beside one core of extra load, and a tally of how each run ended.

    .venv/bin/python -m benchmarks.load_tally [--test-runs 5] [--system-runs 3] [--no-load]

The extra load is one process spinning on one core for the whole tally (``--no-load``: none,
for the unloaded time). Every run's outcome (passed, or the tests that failed or erred, read
from pytest's summary) and its wall time are printed as they end, and a table at the end;
a failed run's whole output is kept in ``$TMPDIR/stb-load-tally/<target>-<n>.log``.
Issue 39's goal: five ``make test`` and three ``make test-system`` in a row pass beside the
load, and ``make test`` takes ≤ 5 minutes unloaded. A full tally takes about 1 h 45 min on the
project's 2-core machine. Exit status: 0 if every run passed.
"""

from __future__ import annotations

import argparse
import multiprocessing
import re
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from multiprocessing.synchronize import Event as StopEvent
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
LOGS = Path(tempfile.gettempdir()) / "stb-load-tally"  # a failed run's whole output
FAILED = re.compile(r"^(FAILED|ERROR) (\S+)", re.MULTILINE)
SUMMARY = re.compile(r"^=+ (.*) in [\d.]+s", re.MULTILINE)


@dataclass
class Outcome:
    target: str
    seconds: float
    passed: bool
    summary: str
    failures: list[str]
    output: str


def _spin(stop: StopEvent) -> None:
    while not stop.is_set():
        sum(range(10_000))


def run(target: str, timeout_s: float) -> Outcome:
    started = time.monotonic()
    try:
        done = subprocess.run(["make", target], cwd=ROOT, capture_output=True, text=True,
                              timeout=timeout_s, check=False)
        out, code = done.stdout + done.stderr, done.returncode
    except subprocess.TimeoutExpired as err:
        seen = err.stdout.decode(errors="replace") if isinstance(err.stdout, bytes) else ""
        out, code = f"{seen}\ntimed out after {timeout_s:.0f} s", -1
    summaries = SUMMARY.findall(out)
    last = out.strip().splitlines()[-1] if out.strip() else ""
    return Outcome(target, time.monotonic() - started, code == 0,
                   summaries[-1] if summaries else last,
                   [name for _, name in FAILED.findall(out)], out)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--test-runs", type=int, default=5)
    parser.add_argument("--system-runs", type=int, default=3)
    parser.add_argument("--no-load", action="store_true", help="no extra load")
    args = parser.parse_args()
    stop = multiprocessing.Event()
    spinner = None if args.no_load else multiprocessing.Process(target=_spin, args=(stop,),
                                                                  daemon=True)
    if spinner is not None:
        spinner.start()
    outcomes = []
    try:
        for target, count, timeout_s in (("test", args.test_runs, 1800),
                                         ("test-system", args.system_runs, 3600)):
            for n in range(1, count + 1):
                outcome = run(target, timeout_s)
                outcomes.append(outcome)
                print(f"make {target} #{n}: {'passed' if outcome.passed else 'FAILED'} in "
                      f"{outcome.seconds / 60:.1f} min — {outcome.summary}"
                      + "".join(f"\n    {name}" for name in outcome.failures), flush=True)
                if not outcome.passed:  # what failed, to read afterwards
                    log = LOGS / f"{target}-{n}.log"
                    log.parent.mkdir(parents=True, exist_ok=True)
                    log.write_text(outcome.output)
                    print(f"    output: {log}", flush=True)
    finally:
        stop.set()
        if spinner is not None:
            spinner.join(5)
    print("\n| run | load | result | minutes |\n|---|---|---|---:|")
    for outcome in outcomes:
        print(f"| make {outcome.target} | {'none' if args.no_load else 'one busy core'} | "
              f"{'passed' if outcome.passed else 'failed: ' + ', '.join(outcome.failures)} | "
              f"{outcome.seconds / 60:.1f} |")
    passed = sum(o.passed for o in outcomes)
    print(f"\n{passed} of {len(outcomes)} passed")
    return 0 if passed == len(outcomes) else 1


if __name__ == "__main__":
    sys.exit(main())
