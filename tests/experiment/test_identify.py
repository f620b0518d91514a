"""``stb experiment identify``: its parameters and ranges, how a fit is scored, that the fit
stays in its ranges and finds a known optimum, and the command on one seed."""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import pytest

from services.experiment.cli import main
from services.experiment.identify import (
    BY_NAME,
    PARAMETERS,
    Evaluation,
    apply,
    commissioned,
    current_values,
    fit,
)
from services.experiment.identify_cli import parse_seeds
from services.experiment.paper import TABLES
from services.gantry.settings import GantrySettings
from services.sim.crane import ramp_following_s
from services.sim.settings import SimSettings


def test_every_parameter_has_a_range_a_reason_and_a_setting() -> None:
    values = current_values(GantrySettings(), SimSettings())
    assert set(values) == set(BY_NAME)
    for p in PARAMETERS:
        assert p.low < p.high and p.why
        assert p.low <= values[p.name] <= p.high, f"the default of {p.name} is in its range"


def test_applied_values_reach_the_sim_and_commission_the_gantry() -> None:
    gantry, sim = apply({"crane.max_accel_mm_s2": 1234.0, "crane.dead_time_s": 0.07,
                         "crane.position_time_constant_s": 0.05, "walker.sway_mm": 7.0,
                         "locomotive.radius_mm": 800.0,
                         "pf_velocity.diff_max_mm": 222.0}, GantrySettings(), SimSettings())
    assert sim.crane.max_accel_mm_s2 == 1234.0 and sim.walker.sway_mm == 7.0
    assert sim.locomotive.radius_mm == 800.0
    assert gantry.pf_velocity.diff_max_mm == 222.0
    assert gantry.pf_position.diff_max_mm == GantrySettings().pf_position.diff_max_mm
    assert gantry.max_accel_mm_s2 == 1234.0, "the guard at the crane's limit"
    assert gantry.reaction_s == pytest.approx(ramp_following_s(sim.crane.params()), abs=0.001)
    assert gantry.reaction_s > 0.12, "dead time and position loop, and the acceleration limit"


def _evaluation(scale: Mapping[str, float], values: Mapping[str, float] | None = None
                ) -> Evaluation:
    std = {sc: {a: (px * scale.get(a, 1.0), py * scale.get(a, 1.0))
                for a, (px, py) in algs.items()} for sc, algs in TABLES.items()}
    return Evaluation(dict(values or {}), std, (1,))


def test_a_fit_is_scored_by_its_log_ratios_and_its_worst_value() -> None:
    exact = _evaluation({})
    assert exact.cost == 0.0 and exact.worst == 0.0
    within = _evaluation({"basic": 1.25})
    assert within.worst == pytest.approx(0.25)
    assert within.cost == pytest.approx(4 * math.log(1.25) ** 2 / 12)
    outside = _evaluation({"basic": 1.35})
    beyond = math.log(1.35) - math.log(1.3)
    assert outside.cost == pytest.approx(4 * math.log(1.35) ** 2 / 12 + 10 * 4 * beyond ** 2)


class _Bowl:
    """A known cost landscape over the parameters' scaled ranges (minimum at 0.3 of each)."""

    def __init__(self) -> None:
        self.seen: list[dict[str, float]] = []

    def __call__(self, values: Mapping[str, float]) -> Evaluation:
        return self.many([values])[0]

    def many(self, candidates: list[Mapping[str, float]]) -> list[Evaluation]:
        out = []
        for values in candidates:
            self.seen.append(dict(values))
            u = np.array([(values[p.name] - p.low) / (p.high - p.low) for p in PARAMETERS])
            out.append(_evaluation({"basic": float(np.exp(np.sqrt(np.sum((u - 0.3) ** 2))))},
                                   values))
        return out


def test_the_fit_stays_in_the_ranges_and_finds_the_optimum() -> None:
    bowl = _Bowl()
    start = {p.name: p.high for p in PARAMETERS}
    best = fit(bowl, start, evaluations=1500, seed=3)  # type: ignore[arg-type]
    assert len(bowl.seen) <= 1500
    for values in bowl.seen:
        assert all(BY_NAME[n].low <= v <= BY_NAME[n].high for n, v in values.items())
    for p in PARAMETERS:
        assert (best.values[p.name] - p.low) / (p.high - p.low) == pytest.approx(0.3, abs=0.02)


def test_seeds_are_read_as_ranges_or_lists() -> None:
    assert parse_seeds("1-5") == (1, 2, 3, 4, 5)
    assert parse_seeds("2,7") == (2, 7)
    with pytest.raises(ValueError, match="expected"):
        parse_seeds("one")


@pytest.mark.system  # 11 s: out of make test's quick loop
def test_the_command_evaluates_the_sim_against_the_tables(tmp_path: Path, crater_file: Path,
                                                          capsys) -> None:  # noqa: ANN001
    out = tmp_path / "fit.json"
    code = main(["identify", "--seeds", "1", "--workers", "2", "--crater", str(crater_file),
                 "--out", str(out), "--json"])
    report = json.loads(capsys.readouterr().out)
    assert code == (0 if report["within_tolerance"] else 1)
    assert json.loads(out.read_text()) == report
    for scenario, algs in TABLES.items():
        assert set(report["std_mm"][scenario]) == set(algs)
    assert set(report["values"]) == set(BY_NAME)


def test_a_walker_that_swings_harder_than_a_tenth_of_g_is_not_run() -> None:
    from services.experiment.identify import GAIT_ACCEL_MM_S2, implausible

    calm = {"walker.step_hz": 1.0, "walker.sway_mm": 10.0, "walker.surge_mm": 1.0}
    assert implausible(calm) == 0.0  # 10·(2π)² + 1·(4π)² ≈ 553 mm/s²
    wild = {"walker.step_hz": 1.3, "walker.sway_mm": 11.2, "walker.surge_mm": 25.5}
    accel = 11.2 * (2 * math.pi * 1.3) ** 2 + 25.5 * (4 * math.pi * 1.3) ** 2
    assert implausible(wild) == pytest.approx(accel / GAIT_ACCEL_MM_S2 - 1)
    evaluation = Evaluation(wild, {}, (1,), implausible(wild))
    assert evaluation.cost > 1000 and evaluation.worst == float("inf")


def test_the_fits_candidates_are_repaired_to_a_plausible_gait() -> None:
    from services.experiment.identify import implausible, plausible

    wild = {"walker.step_hz": 1.3, "walker.sway_mm": 11.2, "walker.surge_mm": 25.5,
            "walker.speed_mm_s": 30.0}
    repaired = plausible(wild)
    assert implausible(repaired) == 0.0 and repaired["walker.speed_mm_s"] == 30.0
    assert repaired["walker.sway_mm"] / repaired["walker.surge_mm"] == pytest.approx(
        11.2 / 25.5, rel=1e-3), "scaled together"


def test_the_gantrys_defaults_are_the_identified_crane_as_commissioning_measures_it() -> None:
    gantry = GantrySettings()
    for name, value in commissioned(SimSettings()).items():
        assert getattr(gantry, name) == pytest.approx(value, abs=0.001), name
