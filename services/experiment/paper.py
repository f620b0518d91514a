"""The paper's gantry results (§3.3): standard deviation of the crane's error per axis, mm."""

from __future__ import annotations

from common.names import AlgorithmName

TABLES: dict[str, dict[str, tuple[float, float]]] = {
    "locomotive": {  # Table 3
        "basic": (68.0, 62.5), "pf-position": (94.0, 97.1), "pf-velocity": (59.4, 53.2)},
    "walker": {  # Table 4
        "basic": (46.3, 50.9), "pf-position": (9.41, 13.1), "pf-velocity": (28.0, 30.8)},
}
PAPER_ALGORITHMS: tuple[AlgorithmName, ...] = ("basic", "pf-position", "pf-velocity")
SCENARIOS = ("locomotive", "walker")

ORDERS: dict[str, tuple[str, ...]] = {
    "locomotive": ("pf-velocity", "basic", "pf-position"),  # best first (Table 3)
    "walker": ("pf-position", "pf-velocity", "basic"),  # Table 4
}


def paper_rms_mm(scenario: str, algorithm: str) -> float:
    """The rms error length the paper's standard deviations amount to (zero-mean errors)."""
    sx, sy = TABLES[scenario][algorithm]
    return (sx * sx + sy * sy) ** 0.5
