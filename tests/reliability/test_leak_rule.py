"""The campaign's leak rule: a repeated fault counts a service's least growth over its rounds."""

from __future__ import annotations

from benchmarks.faults.rows import GOAL_FLAT_MB, least_growth


def test_a_leak_grows_in_every_round_and_is_caught() -> None:
    rounds = [({"sim": 100.0, "web": 80.0}, {"sim": 107.0, "web": 80.5}),
              ({"sim": 107.0, "web": 80.5}, {"sim": 113.5, "web": 80.6})]
    service, grown = least_growth(rounds)
    assert (service, grown) == ("sim", 6.5)
    assert grown > GOAL_FLAT_MB


def test_a_high_water_mark_reached_once_is_not_a_leak() -> None:
    # the CI run that taught this: the sim grew 5.8 MB once (one round), then not again
    rounds = [({"sim": 100.0, "web": 80.0}, {"sim": 105.8, "web": 80.3}),
              ({"sim": 105.8, "web": 80.3}, {"sim": 105.9, "web": 80.5})]
    service, grown = least_growth(rounds)
    assert service == "web" and abs(grown - 0.2) < 1e-9
    assert grown <= GOAL_FLAT_MB


def test_one_round_is_its_own_growth() -> None:
    assert least_growth([({"a": 1.0, "b": 2.0}, {"a": 4.0, "b": 2.5})]) == ("a", 3.0)
