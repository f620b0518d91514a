"""The gantry's estimation algorithms by name (light: command lines offer them before numpy
loads; services/gantry/predict.py implements them)."""

from __future__ import annotations

from typing import Literal, get_args

AlgorithmName = Literal["basic", "pf-position", "pf-position-gauss", "pf-velocity", "default"]
ALGORITHMS: tuple[AlgorithmName, ...] = get_args(AlgorithmName)
