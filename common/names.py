"""The names the services and their command lines share, each defined once (light: no
pydantic or numpy, so that ``--help`` offers them; ``common.messages`` uses them on the wire).
"""

from __future__ import annotations

from typing import Literal, get_args

AlgorithmName = Literal["basic", "pf-position", "pf-position-gauss", "pf-velocity", "default"]
ALGORITHMS: tuple[AlgorithmName, ...] = get_args(AlgorithmName)
"""The gantry's estimation algorithms (services/gantry/predict.py implements them)."""

GantryMode = Literal["disarmed", "armed", "stopped"]
"""Who may move the crane (services/gantry/modes.py)."""

GantryCommandName = Literal["arm", "disarm", "stop", "reset"]
GANTRY_COMMANDS: tuple[GantryCommandName, ...] = get_args(GantryCommandName)
"""The operator's commands to the gantry, in their order of the help texts."""
