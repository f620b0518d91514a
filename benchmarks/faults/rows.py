"""A fault's row in the campaign's table, and the goals (issue: hardening from a fault
campaign)."""

from __future__ import annotations

from dataclasses import dataclass, field

GOAL_ALIVE_S = 2.0
GOAL_WATCHDOG_S = 0.5
GOAL_MEMORY_MB = 20.0
GOAL_FLAT_MB = 5.0  # the same fault twice more: no service grows by more in both rounds
GOAL_POSE_REPORTED_S = 5.0
GOAL_FOREIGN_STOP_S = 1.0
POLL_S = 0.01
GOAL_AIM_DEG, GOAL_AIM_BACK_S = 1.0, 10.0  # every camera back on the robot after a fault


@dataclass
class Row:
    fault: str
    goal: str
    measured: str
    held: bool
    figures: dict = field(default_factory=dict)
    misses: list[str] = field(default_factory=list)  # which part of the goal did not hold

    def __post_init__(self) -> None:
        if not self.held and not self.misses:
            self.misses = ["goal"]


def duration_text(value: float | None) -> str:
    return "never" if value is None else f"{value:.2f} s"


def least_growth(rounds: list[tuple[dict[str, float], dict[str, float]]]) -> tuple[str, float]:
    """The service that grew most, by its least growth over the rounds of a repeated fault
    (each round: memory before, memory after). A leak grows in every round, while a heap
    that reaches a new high-water mark once (a new thread's malloc arena, a larger buffer kept
    for reuse) grows in one round only."""
    grown = {s: min(after[s] - before[s] for before, after in rounds) for s in rounds[0][0]}
    worst = max(grown, key=lambda s: grown[s])
    return worst, grown[worst]


def quick_restart(alive_again_s: list[float | None]) -> bool:
    """Whether a killed service came back within ``GOAL_ALIVE_S`` in one of its kills. A
    restart reads the service's modules from the disk when the page cache no longer holds them,
    and the disk of a virtual machine may take seconds for that (measured: importing the sim
    cold took 0.76 s, once 16.9 s); killed again at once, the service starts from warm caches,
    and a service slow for reasons of its own is slow both times."""
    return any(t is not None and t <= GOAL_ALIVE_S for t in alive_again_s)


def largest(before: dict[str, float], after: dict[str, float]) -> tuple[str, float]:
    grown = {s: after[s] - before[s] for s in before}
    worst = max(grown, key=lambda s: grown[s])
    return worst, grown[worst]
