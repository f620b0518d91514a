"""The gantry service against the sim's Modbus crane controller (tests/gantry/rig.py)."""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest

from common import keys
from common import messages as m
from common.bus import Bus
from common.crane_frame import CraneConnection
from common.heightmap import HeightMap
from common.node import Node
from services.gantry.service import run
from services.gantry.settings import GantrySettings
from tests.gantry.rig import GROUND_MM, MARKER_MM, CraneRig, Operator


@pytest.fixture
def flat_map(tmp_path: Path) -> Path:
    heights = tmp_path / "flat.npz"
    HeightMap(np.full((3, 3), GROUND_MM, np.float32), -5000, -5000, 5000).save(heights)
    return heights


@pytest.fixture
def rig(request: pytest.FixtureRequest, flat_map: Path, make_bus: Callable[..., Bus],
        compiled_detector: None) -> Iterator[dict]:
    """The gantry service against a CraneRig; ``indirect`` parameters: more settings (and
    ``registers``: the map both sides use)."""
    extra = dict(getattr(request, "param", {}))
    if "crane" in extra:  # the lab's register map, in the world's frame
        extra["crane"] = CraneConnection(**extra["crane"].model_dump())
    crane = CraneRig(extra["crane"]) if "crane" in extra else CraneRig()
    # The tests' operator sends as fast as a test runs (reset, arm, … in a row): the lab's
    # command rate (5 at once, 2 a second) is the subject of test_command_rate.py, which sets
    # it; elsewhere it would only make a busy machine's run fail.
    extra = {"command_burst": 100, "command_per_s": 100.0, **extra}
    settings = GantrySettings(crane_port=crane.port, height_map=flat_map,
                              marker_height_mm=MARKER_MM, stale_after_s=0.6, **extra)
    node = Node("gantry", settings, make_bus())
    world = make_bus()
    setpoints: list[m.CraneSetpoint] = []
    world.subscribe(keys.GANTRY_SETPOINT, setpoints.append, latest=False)
    thread = threading.Thread(target=run, args=(node,), daemon=True)
    thread.start()
    yield {"crane": crane, "node": node, "world": world, "setpoints": setpoints,
           "thread": thread, "operator": Operator(make_bus()), "settings": settings}
    node.stop.set()
    thread.join(5)
    crane.close()
