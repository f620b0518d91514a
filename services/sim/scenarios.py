"""The sim's scenarios by name (light: the command line offers them before numpy loads)."""

from __future__ import annotations

from typing import Literal, get_args

Scenario = Literal["locomotive", "walker", "calibration", "parked", "figure8", "stop-and-go",
                   "zigzag", "wander", "slides"]
SCENARIOS: tuple[Scenario, ...] = get_args(Scenario)
FOLLOWED: tuple[Scenario, ...] = ("locomotive", "walker", "figure8", "stop-and-go", "zigzag",
                                  "wander", "slides")
"""The scenarios with a robot for the crane to follow: the paper's two, then ours
(``rovers.py``)."""
