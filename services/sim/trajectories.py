"""Each scenario's robot path by name (the paper's two robots, ``robots.py``; more,
``rovers.py``; the wand and the parked robot)."""

from __future__ import annotations

import numpy as np

from services.sim import rovers
from services.sim.robots import Railway, Trajectory, Walk, calibration, locomotive, parked, walker
from services.sim.scenarios import Scenario
from services.sim.world import CraterMap


def make_trajectory(scenario: Scenario, world: CraterMap, rng: np.random.Generator, *,
                    railway: Railway = Railway(), walk: Walk = Walk()) -> Trajectory:
    if scenario == "locomotive":
        return locomotive(world, railway)
    if scenario == "walker":
        return walker(world, rng, walk)
    if scenario == "slides":
        return rovers.sliding_walker(world, rng, walk)
    if scenario == "figure8":
        return rovers.figure_eight(world)
    if scenario == "stop-and-go":
        return rovers.stop_and_go(world, rng)
    if scenario == "zigzag":
        return rovers.zigzag(world)
    if scenario == "wander":
        return rovers.wander(world, rng)
    if scenario == "parked":
        return parked(world)
    return calibration(world, rng)
