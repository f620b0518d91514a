"""Identify the simulated crane and robots against the paper's Tables 3 and 4.

The paper's three algorithms (``basic``, ``pf-position``, ``pf-velocity``) run in the gantry
experiment exactly as the gantry runs them; the sim's parameters below are fitted so that
their error standard deviations (std x, std y; 3 algorithms × 2 scenarios = 12 values,
averaged over seeds) match the paper's. ``default`` plays no part.

Every parameter has a range fixed before the fit, each physically plausible for a lab gantry
and its robots (``PARAMETERS``: the reason is stated beside each), and no candidate's walker
swings its body harder than ``GAIT_ACCEL_MM_S2`` (the fit scales its sway and surge down to
that; the evaluation of given values refuses to run them). The gantry's own settings
follow the crane as its commissioning would set them: the setpoint guard's speed and
acceleration limits are the crane's, its reaction time what ``stb gantry identify``
measures on it (``ramp_following_s``).
"""

from __future__ import annotations

import math
import multiprocessing
import time
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from common.names import AlgorithmName
from services.experiment.paper import PAPER_ALGORITHMS, SCENARIOS, TABLES
from services.gantry.settings import GantrySettings
from services.sim.crane import ramp_following_s
from services.sim.settings import SimSettings

TOLERANCE = 0.30
"""Each of the 12 values within ±30 % of the paper's."""


@dataclass(frozen=True)
class Parameter:
    name: str  # "<section>.<field>": a field of [sim.crane], [sim.walker], [sim.locomotive],
    # [gantry.pf_position] or [gantry.pf_velocity]
    low: float
    high: float
    why: str


PARAMETERS: tuple[Parameter, ...] = (
    Parameter("crane.dead_time_s", 0.0, 0.3,
              "setpoint sampled → axes start: PLC and drive cycles (paper: reaction ~0.5 s "
              "in all, with the 4 Hz sampling and the motion)"),
    Parameter("crane.position_time_constant_s", 0.0, 0.3,
              "an industrial axis' position loop: 3–30 rad/s bandwidth or a flat-out profile"),
    Parameter("crane.report_latency_s", 0.0, 0.2,
              "age of the published position: a fieldbus and a PLC cycle or two"),
    Parameter("crane.report_jitter_s", 0.0, 0.2,
              "its spread: the paper's 'exact time of measurement ... roughly known'"),
    Parameter("crane.max_accel_mm_s2", 500.0, 5000.0, "gantry drives: 0.5–5 m/s²"),
    Parameter("crane.max_speed_mm_s", 350.0, 1000.0,
              "must exceed the locomotive's 290 mm/s; gantry axes: up to ~1 m/s"),
    Parameter("walker.speed_mm_s", 10.0, 100.0, "a walking planetary robot: 1–10 cm/s"),
    Parameter("walker.step_hz", 0.3, 1.5, "its gait cycle"),
    Parameter("walker.sway_mm", 0.0, 40.0, "sideways body sway of a legged robot"),
    Parameter("walker.surge_mm", 0.0, 40.0, "forward-and-back body motion per step"),
    Parameter("walker.slide_per_s", 0.0, 0.1, "slips on slopes over 28°: up to one per 10 s"),
    Parameter("walker.slide_speed_mm_s", 100.0, 500.0, "'a little faster downhill'"),
    Parameter("locomotive.straight_mm", 0.0, 2000.0, "a model railway oval in an 8 × 8 m "
              "crater (the paper gives no plan)"),
    Parameter("locomotive.radius_mm", 500.0, 1500.0, "garden-railway curves: R 0.6–1.5 m"),
    Parameter("pf_position.velocity_noise_mm_s", 1.0, 300.0,
              "eq. 11's v_n for the position filter: the paper gives none"),
    Parameter("pf_position.diff_max_mm", 30.0, 1000.0, "eq. 12's diff_max: none given"),
    Parameter("pf_velocity.velocity_noise_mm_s", 1.0, 300.0, "the same for the velocity "
              "filter (the paper tuned each algorithm's parameters on the locomotive)"),
    Parameter("pf_velocity.diff_max_mm", 30.0, 1000.0, "eq. 12's diff_max: none given"),
)
BY_NAME = {p.name: p for p in PARAMETERS}
GAIT_ACCEL_MM_S2 = 1000.0
"""A slow walking robot's body does not swing harder than 0.1 g: its sway (once per gait
cycle) and surge (twice) together stay below this peak acceleration."""


def plausible(values: dict[str, float]) -> dict[str, float]:
    """``values`` with the walker's sway and surge scaled down together until its gait is
    within ``GAIT_ACCEL_MM_S2`` (the fit's candidates are repaired, not thrown away)."""
    excess = implausible(values)
    if not excess:
        return values
    scale = 1.0 / (1.0 + excess) * 0.999
    return {**values, **{k: round(values[k] * scale, 4) for k in ("walker.sway_mm",
                                                                  "walker.surge_mm")
                         if k in values}}


def implausible(values: Mapping[str, float]) -> float:
    """How far ``values`` break the plausibility limits (0: they do not), in units of the
    limit: the walker's gait acceleration."""
    omega = 2 * math.pi * values.get("walker.step_hz", 1.0)
    accel = (values.get("walker.sway_mm", 0.0) * omega ** 2
             + values.get("walker.surge_mm", 0.0) * (2 * omega) ** 2)
    return max(0.0, accel / GAIT_ACCEL_MM_S2 - 1.0)


def current_values(gantry: GantrySettings, sim: SimSettings) -> dict[str, float]:
    """The parameters as the given settings have them."""
    sections = {"crane": sim.crane, "walker": sim.walker, "locomotive": sim.locomotive,
                "pf_position": gantry.pf_position, "pf_velocity": gantry.pf_velocity}
    return {p.name: float(getattr(sections[p.name.split(".")[0]], p.name.split(".")[1]))
            for p in PARAMETERS}


def apply(values: Mapping[str, float], gantry: GantrySettings, sim: SimSettings
          ) -> tuple[GantrySettings, SimSettings]:
    """The settings with ``values`` in place, and the gantry commissioned for that crane."""
    updates: dict[str, dict[str, float]] = {}
    for name, value in values.items():
        section, field_name = name.split(".")
        updates.setdefault(section, {})[field_name] = value
    crane = sim.crane.model_copy(update=updates.get("crane", {}))
    sim = sim.model_copy(update={
        "crane": crane,
        "walker": sim.walker.model_copy(update=updates.get("walker", {})),
        "locomotive": sim.locomotive.model_copy(update=updates.get("locomotive", {}))})
    gantry = gantry.model_copy(update={
        "pf_position": gantry.pf_position.model_copy(update=updates.get("pf_position", {})),
        "pf_velocity": gantry.pf_velocity.model_copy(update=updates.get("pf_velocity", {})),
        **commissioned(sim)})
    return gantry, sim


def commissioned(sim: SimSettings) -> dict[str, float]:
    """What commissioning (``stb gantry identify``) sets the gantry to for the sim's crane."""
    params = sim.crane.params()
    return {"max_speed_mm_s": params.max_speed_mm_s, "max_accel_mm_s2": params.max_accel_mm_s2,
            "reaction_s": round(ramp_following_s(params), 3),
            "report_age_s": round(params.report_latency_s, 3)}


@dataclass(frozen=True)
class Evaluation:
    values: dict[str, float]
    std_mm: dict[str, dict[str, tuple[float, float]]]  # scenario → algorithm → (x, y), mean
    seeds: tuple[int, ...]
    broken: float = 0.0  # how far the values break the plausibility limits (then not run)

    @property
    def ratios(self) -> dict[str, dict[str, tuple[float, float]]]:
        """sim / paper per value."""
        return {sc: {a: (sx / TABLES[sc][a][0], sy / TABLES[sc][a][1])
                     for a, (sx, sy) in algs.items()} for sc, algs in self.std_mm.items()}

    @property
    def worst(self) -> float:
        """The largest relative deviation from the paper's value (0.3 = 30 %)."""
        if self.broken:
            return float("inf")
        return max(abs(r - 1.0) for algs in self.ratios.values() for pair in algs.values()
                   for r in pair)

    @property
    def cost(self) -> float:
        """Mean squared log ratio, plus a steep price for every value outside ±30 %; an
        implausible candidate costs more than any plausible one."""
        if self.broken:
            return 1000.0 * (1.0 + self.broken)
        logs = [math.log(r) for algs in self.ratios.values() for pair in algs.values()
                for r in pair]
        outside = [max(0.0, abs(v) - math.log(1 + TOLERANCE)) for v in logs]
        return float(np.mean(np.square(logs)) + 10 * np.sum(np.square(outside)))


Job = tuple[dict[str, float], str, AlgorithmName, int, GantrySettings, SimSettings, Path]


def _run_job(job: Job) -> tuple[float, float]:
    from services.experiment.gantry import run_scenario

    values, scenario, algorithm, seed, gantry, sim, crater = job
    gantry, sim = apply(values, gantry, sim)
    s = run_scenario(scenario, algorithm, seed=seed, crater_file=crater, gantry=gantry,
                     sim=sim).summary()
    return s["std_x_mm"], s["std_y_mm"]


class Evaluator:
    """Runs the 3 × 2 experiments per seed for a set of parameter values, on ``workers``
    processes."""

    def __init__(self, gantry: GantrySettings, sim: SimSettings, crater: Path,
                 seeds: Iterable[int], workers: int = 2) -> None:
        self.gantry, self.sim, self.crater = gantry, sim, crater
        self.seeds = tuple(seeds)
        self._pool = multiprocessing.get_context("fork").Pool(workers) if workers > 1 else None

    def close(self) -> None:
        if self._pool is not None:
            self._pool.close()
            self._pool.join()

    def __call__(self, values: Mapping[str, float]) -> Evaluation:
        return self.many([values])[0]

    def many(self, candidates: list[Mapping[str, float]]) -> list[Evaluation]:
        """Each candidate's evaluation; an implausible one is not run (``Evaluation.broken``)."""
        runnable = [dict(v) for v in candidates if not implausible(v)]
        jobs: list[Job] = [(v, sc, a, seed, self.gantry, self.sim, self.crater)
                           for v in runnable for sc in SCENARIOS for a in PAPER_ALGORITHMS
                           for seed in self.seeds]
        results = self._pool.map(_run_job, jobs) if self._pool else list(map(_run_job, jobs))
        per = len(SCENARIOS) * len(PAPER_ALGORITHMS) * len(self.seeds)
        done = iter(self._evaluation(v, jobs[i * per:(i + 1) * per],
                                     results[i * per:(i + 1) * per])
                    for i, v in enumerate(runnable))
        return [Evaluation(dict(v), {}, self.seeds, implausible(v)) if implausible(v)
                else next(done) for v in candidates]

    def _evaluation(self, values: dict[str, float], jobs: list[Job],
                    results: list[tuple[float, float]]) -> Evaluation:
        runs: dict[str, dict[str, list[tuple[float, float]]]] = {}
        for job, result in zip(jobs, results, strict=True):
            runs.setdefault(job[1], {}).setdefault(job[2], []).append(result)
        std = {sc: {a: tuple(np.mean(r, axis=0).round(2)) for a, r in algs.items()}
               for sc, algs in runs.items()}
        return Evaluation(values, std, self.seeds)


def fit(evaluate: Evaluator, start: Mapping[str, float], *, evaluations: int, seed: int = 1,
        progress: Callable[[int, Evaluation, Evaluation], None] | None = None) -> Evaluation:
    """CMA-ES over the parameters scaled to [0, 1] within their ranges, from ``start``;
    at most ``evaluations`` (whole generations; fewer if CMA-ES converges). Returns the best
    evaluation."""
    import cma

    names = [p.name for p in PARAMETERS]
    low = np.array([BY_NAME[n].low for n in names])
    span = np.array([BY_NAME[n].high for n in names]) - low

    def values_of(u: np.ndarray) -> dict[str, float]:
        return plausible({n: round(float(v), 4) for n, v in zip(
            names, low + span * np.clip(u, 0, 1), strict=True)})

    x0 = np.clip((np.array([start[n] for n in names]) - low) / span, 0, 1)
    best = evaluate(values_of(x0))
    done = 1
    if progress:
        progress(done, best, best)
    es = cma.CMAEvolutionStrategy(x0, 0.15, {"bounds": [0, 1], "seed": seed, "verbose": -9,
                                             "maxfevals": max(evaluations - 1, 1)})
    while not es.stop() and done + es.popsize <= evaluations:  # whole generations only
        xs = es.ask()
        results = evaluate.many([values_of(x) for x in xs])
        es.tell(xs, [r.cost for r in results])
        for r in results:
            done += 1
            best = min(best, r, key=lambda e: e.cost)
            if progress:
                progress(done, r, best)
    return best


def elapsed(started: float) -> str:
    seconds = time.monotonic() - started
    return f"{seconds / 60:.1f} min" if seconds >= 60 else f"{seconds:.0f} s"
