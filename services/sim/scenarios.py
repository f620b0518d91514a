"""The sim's scenarios by name (light: the command line offers them before numpy loads)."""

from __future__ import annotations

from typing import Literal, get_args

Scenario = Literal["locomotive", "walker", "calibration", "parked"]
SCENARIOS: tuple[Scenario, ...] = get_args(Scenario)
