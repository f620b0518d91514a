"""The paper's gantry experiments (§3.3) on a simulated clock, much faster than real time.

The gantry's own loop runs with the lab's gantry settings — ``GantryLoop`` polling the crane
controller's report at ``poll_hz`` and ticking ``after_report_s`` after each new one
(``CycleSync``), its ``Controller`` detecting, picking, locating, predicting and guarding, armed
as an operator would arm it once the robot is in view —
against the sim's crane controller (its register map, on the simulated clock) and the sim's
tracking camera (frames that arrive ``delay_s`` after their exposure, as over the bus). Only
the wire and the waiting are left out. The crane-to-robot error is sampled at 20 Hz.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from common.heightmap import HeightMap
from common.markers import warm_up
from common.names import AlgorithmName
from services.experiment.devices import ModelCrane, SimClock, SimCraneMarker, SimFrames
from services.gantry.control import Controller
from services.gantry.cycle import dithered_period_s
from services.gantry.loop import GantryLoop, Request
from services.gantry.predict import Estimate
from services.gantry.settings import GantrySettings
from services.sim.lab import Lab, load_or_make_crater
from services.sim.robots import MARKER_HEIGHT_MM, SAMPLE_HZ, Trajectory
from services.sim.settings import SimSettings

ERROR_SAMPLE_S = 0.05
START_S = 0.2
"""The gantry's first poll: out of step with the controller's cycle (which starts at 0) — its
ticks run free until the crane moves and ``CycleSync`` learns when it reports."""


@dataclass
class Run:
    algorithm: str
    t_s: np.ndarray
    error_mm: np.ndarray  # (N, 2) crane − robot
    velocity_t_s: list[float] = field(default_factory=list)
    velocity_mm_s: list[np.ndarray] = field(default_factory=list)  # the predictor's velocity
    held: int = 0
    ticks: int = 0
    report_age_s: list[float] = field(default_factory=list)  # the crane report's age per tick
    wall_s: float = 0.0

    def summary(self) -> dict:
        e = self.error_mm
        distance = np.hypot(e[:, 0], e[:, 1])
        sim_s = float(self.t_s[-1] - self.t_s[0]) if len(self.t_s) > 1 else 0.0
        return {"algorithm": self.algorithm,
                "std_x_mm": round(float(np.std(e[:, 0])), 2),
                "std_y_mm": round(float(np.std(e[:, 1])), 2),
                "rms_mm": round(float(np.sqrt(np.mean(distance ** 2))), 2),
                "max_mm": round(float(distance.max()), 2),
                "held_ticks": self.held, "ticks": self.ticks,
                "report_age_s": round(float(np.median(self.report_age_s)), 3)
                if self.report_age_s else None,
                "sim_s": round(sim_s, 2), "wall_s": round(self.wall_s, 3),
                "speedup": round(sim_s / self.wall_s, 1) if self.wall_s > 0 else None}


def make_lab(scenario: str, seed: int, crater_file: Path, sim: SimSettings | None = None
             ) -> Lab:
    """The sim's lab for one run (``sim``: the lab file's sim settings, else the defaults). A
    missing height map is made from the sim's own default seed, not the run's: every
    ``--seed`` runs in the same crater, whichever ran first."""
    sim = sim or SimSettings()
    crater = load_or_make_crater(SimSettings(crater_file=crater_file))
    settings = sim.model_copy(update={"scenario": scenario, "seed": seed, "loop": False,
                                      "crater_file": crater_file, "calibrate_first": []})
    return Lab.build(settings, crater)


def gantry_for(base: GantrySettings, algorithm: AlgorithmName, *, seed: int,
               marker_height_mm: float) -> GantrySettings:
    """The lab's gantry settings for one run: its algorithm, the particle filters' seed, and
    the height the robot carries its marker at (set per robot, as an operator would)."""
    return base.model_copy(update={"algorithm": algorithm, "seed": seed,
                                   "marker_height_mm": marker_height_mm})


@dataclass
class Oracle:
    """Not an algorithm: each frame's desired position is where the robot truly will be
    ``ahead_s`` after the frame was taken — what no causal predictor can beat, a bound on
    what the crane's delays and limits allow."""

    truth: Callable[[float], np.ndarray]
    ahead_s: float
    name: str = "oracle"

    def update(self, t_s: float, measured: np.ndarray | None, horizon_s: float | None = None,
               noise_mm: float | None = None) -> Estimate:
        now, then = self.truth(t_s)[:2], self.truth(t_s + self.ahead_s)[:2]
        return Estimate(now, (then - now) / self.ahead_s, then)


def run(lab: Lab, settings: GantrySettings, *, end_s: float | None = None,
        oracle_ahead_s: float | None = None,
        progress: Callable[[float], None] | None = None,
        heights: HeightMap | None = None) -> Run:
    """One experiment; ``lab`` is used up (its crane moves). With ``oracle_ahead_s`` the
    predictor is the ``Oracle`` (the bound), not ``settings.algorithm``. ``progress`` is told
    the share of the run done, fifty times a run. ``heights``: the gantry's height map (a lab's
    imported laser scan); None: the sim's crater itself."""
    warm_up()  # load the compiled detector before the clock starts
    started = time.perf_counter()
    clock = SimClock(START_S)
    controller = Controller(settings, lab.crater if heights is None else heights,
                            None if oracle_ahead_s is None else Oracle(lab.robot, oracle_ahead_s))
    crane = ModelCrane(lab.crane, clock, settings.crane, settings.crane.frame())
    loop = GantryLoop(settings, crane,
                      SimFrames(lab, clock, np.random.default_rng((settings.seed, 2))),
                      controller, START_S,
                      crane_marker=SimCraneMarker(lab, clock,
                                                  np.random.default_rng((settings.seed, 3))),
                      clock=clock)  # the simulated time, reads included: reproducible
    arm_asked = False
    end = lab.trajectory.duration_s if end_s is None else end_s
    name = settings.algorithm if oracle_ahead_s is None else f"oracle {oracle_ahead_s:.2f} s"
    result = Run(name, np.array([]), np.zeros((0, 2)))
    samples_t: list[float] = []
    errors: list[np.ndarray] = []
    poll_s = 1 / settings.poll_hz
    dither = np.random.default_rng((settings.seed, 4))  # as the service polls
    every_s, told = (end - START_S) / 50, -1
    t = START_S
    while t <= end:
        if progress is not None and (share := int((t - START_S) / every_s)) > told:
            progress(share / 50)
            told = share
        while len(samples_t) * ERROR_SAMPLE_S < t:  # error samples between polls
            at = len(samples_t) * ERROR_SAMPLE_S
            samples_t.append(at)
            errors.append(lab.crane_state(at)[0] - lab.robot(at)[:2])
        clock.now_s = polled = t
        tick = loop.poll(t)
        t = loop.next_poll_s(t, dithered_period_s(poll_s, float(dither.random())))
        if tick is None or tick.step is None:
            continue
        step = tick.step
        if not arm_asked and step.estimate is not None:  # as an operator would, once in view
            loop.request(Request("arm", "experiment", "the robot is in view"))
            arm_asked = True
        result.report_age_s.append(polled - lab.crane.reported_s)
        if step.estimate is not None and step.frame_s is not None:
            result.velocity_t_s.append(polled)
            result.velocity_mm_s.append(step.estimate.velocity)
        result.held += step.hold
        result.ticks += 1
    result.t_s, result.error_mm = np.array(samples_t), np.array(errors).reshape(-1, 2)
    result.wall_s = time.perf_counter() - started
    return result


def run_scenario(scenario: str, algorithm: AlgorithmName, *, seed: int, crater_file: Path,
                 gantry: GantrySettings | None = None, sim: SimSettings | None = None,
                 path: Trajectory | None = None, oracle_ahead_s: float | None = None,
                 progress: Callable[[float], None] | None = None,
                 gantry_map: Path | None = None) -> Run:
    """One algorithm (or the oracle) on one scenario, or on ``path`` (a recorded or CSV
    path: the walker's marker height if ``scenario`` is the walker, else the locomotive's)."""
    lab = make_lab("locomotive" if path is not None else scenario, seed, crater_file, sim)
    height = MARKER_HEIGHT_MM.get(scenario, MARKER_HEIGHT_MM["locomotive"])
    if path is not None:
        lab.trajectory = on_crater(path, lab, height)
        lab.place_crane(lab.trajectory.position(0.0))
    settings = gantry_for(gantry or GantrySettings(), algorithm, seed=seed,
                          marker_height_mm=height)
    return run(lab, settings, oracle_ahead_s=oracle_ahead_s, progress=progress,
               heights=None if gantry_map is None else HeightMap.load(gantry_map))


def on_crater(path: Trajectory, lab: Lab, marker_height_mm: float) -> Trajectory:
    """A path (x, y over time) on the sim's grid, its marker on the crater's surface."""
    t, xy = path.t_s, path.xyz_mm[:, :2]
    grid = np.arange(t[0], t[-1], 1 / SAMPLE_HZ)
    gx, gy = np.interp(grid, t, xy[:, 0]), np.interp(grid, t, xy[:, 1])
    z = lab.crater.height_at(gx, gy) + marker_height_mm
    return Trajectory(path.name, grid - grid[0], np.column_stack([gx, gy, z]))
