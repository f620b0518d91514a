"""``stb experiment identify``: evaluate or fit the sim against the paper's Tables 3 and 4."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from common.files import write_atomically
from services.experiment.identify import (
    PARAMETERS,
    TOLERANCE,
    Evaluation,
    Evaluator,
    apply,
    current_values,
    elapsed,
    fit,
)
from services.experiment.paper import TABLES
from services.gantry.settings import GantrySettings
from services.sim.settings import SimSettings

PROG = "stb experiment identify"


def identify(args: argparse.Namespace, gantry: GantrySettings, sim: SimSettings) -> int:
    try:
        seeds = parse_seeds(args.seeds)
        start = _start(args.start, gantry, sim)
    except ValueError as err:
        print(f"{PROG}: {err}", file=sys.stderr)
        return 2
    out = sys.stderr if args.json else sys.stdout
    evaluator = Evaluator(gantry, sim, args.crater, seeds, workers=max(args.workers, 1))
    started = time.monotonic()
    try:
        if args.evaluations <= 0:
            print(f"evaluating the current values on seeds {args.seeds} "
                  f"({6 * len(seeds)} runs) …", file=out, flush=True)
            result = evaluator(start)
        else:
            print(f"fitting {len(PARAMETERS)} parameters, at most {args.evaluations} "
                  f"evaluations of {6 * len(seeds)} runs each …", file=out, flush=True)

            def progress(done: int, latest: Evaluation, best: Evaluation) -> None:
                print(f"  {done:4d}/{args.evaluations}  cost {latest.cost:7.3f}  worst "
                      f"{latest.worst:5.0%}   best so far: cost {best.cost:.3f}, worst "
                      f"{best.worst:.0%}   ({elapsed(started)})", file=out, flush=True)
                if args.out and best is latest:  # kept as it goes: a long fit may be cut short
                    _write(args.out, _report(best, gantry, sim, time.monotonic() - started))

            result = fit(evaluator, start, evaluations=args.evaluations, progress=progress)
    finally:
        evaluator.close()
    report = _report(result, gantry, sim, time.monotonic() - started)
    if args.out:
        _write(args.out, report)
    if args.json:
        print(json.dumps(report))
    else:
        print(_table(result), flush=True)
        print("\nas lab-file settings:\n" + _toml(result, gantry, sim))
    return 0 if result.worst <= TOLERANCE else 1


def _write(path: Path, report: dict) -> None:
    write_atomically(path, (json.dumps(report, indent=1) + "\n").encode())


def parse_seeds(text: str) -> tuple[int, ...]:
    """``1-5`` or ``1,3,7``."""
    try:
        if "-" in text:
            first, last = (int(v) for v in text.split("-", 1))
            seeds = tuple(range(first, last + 1))
        else:
            seeds = tuple(int(v) for v in text.split(","))
    except ValueError:
        raise ValueError(f"--seeds {text!r}: expected e.g. 1-5 or 1,3,7") from None
    if not seeds:
        raise ValueError(f"--seeds {text!r}: no seed")
    return seeds


def _start(path: Path | None, gantry: GantrySettings, sim: SimSettings) -> dict[str, float]:
    values = current_values(gantry, sim)
    if path is None:
        return values
    try:
        given = json.loads(path.read_text())["values"]
    except (OSError, ValueError, KeyError, TypeError) as err:
        raise ValueError(f"--start {path}: not a fit written by --out ({err})") from err
    unknown = set(given) - set(values)
    if unknown:
        raise ValueError(f"--start {path}: unknown parameters {sorted(unknown)}")
    return {**values, **{k: float(v) for k, v in given.items()}}


def _report(result: Evaluation, gantry: GantrySettings, sim: SimSettings, seconds: float
            ) -> dict:
    return {"values": result.values, "seeds": list(result.seeds),
            "cost": round(float(result.cost), 4),
            "worst_deviation": round(float(result.worst), 4), "within_tolerance":
            bool(result.worst <= TOLERANCE), "seconds": round(seconds, 1),
            "std_mm": {sc: {a: list(v) for a, v in algs.items()}
                       for sc, algs in result.std_mm.items()},
            "paper_mm": {sc: {a: list(v) for a, v in algs.items()}
                         for sc, algs in TABLES.items()},
            "ranges": {p.name: [p.low, p.high] for p in PARAMETERS}}


def _table(result: Evaluation) -> str:
    lines = [f"\n{'scenario':<11} {'algorithm':<12} {'paper std x / y':>17} "
             f"{'sim std x / y':>17} {'sim / paper':>13}"]
    for scenario, algs in result.std_mm.items():
        for algorithm, (sx, sy) in algs.items():
            px, py = TABLES[scenario][algorithm]
            rx, ry = result.ratios[scenario][algorithm]
            flag = "" if max(abs(rx - 1), abs(ry - 1)) <= TOLERANCE else "  ← outside ±30 %"
            lines.append(f"{scenario:<11} {algorithm:<12} {px:7.1f} / {py:6.1f}  "
                         f"{sx:7.1f} / {sy:6.1f}  {rx:5.2f} / {ry:4.2f}{flag}")
    verdict = "all within" if result.worst <= TOLERANCE else "NOT all within"
    lines.append(f"{verdict} ±{TOLERANCE:.0%} (worst {result.worst:.0%}); seeds "
                 f"{', '.join(map(str, result.seeds))}")
    return "\n".join(lines)


def _toml(result: Evaluation, gantry: GantrySettings, sim: SimSettings) -> str:
    fitted_gantry, _ = apply(result.values, gantry, sim)
    sections: dict[str, list[str]] = {}
    for name, value in result.values.items():
        section, field_name = name.split(".")
        table = f"gantry.{section}" if section.startswith("pf_") else f"sim.{section}"
        sections.setdefault(table, []).append(f"{field_name} = {value:g}")
    sections["gantry"] = [f"{k} = {getattr(fitted_gantry, k):g}"
                          for k in ("max_speed_mm_s", "max_accel_mm_s2", "reaction_s")]
    return "\n".join(f"[{table}]\n" + "\n".join(lines) + "\n"
                     for table, lines in sections.items())
