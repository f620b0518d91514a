"""The paper's gantry experiments (§3.3) on a simulated clock, much faster than real time.

The whole chain runs in one process with the live system's modules: the gantry polls the
crane controller's reported position (40 Hz) and ticks 0.075 s after each new report (4 Hz,
``CycleSync``), the sim's tracking camera renders a frame at every tick from the robot's
marker and the crane's position, the shared detector finds the marker (closest to the last
one), eq. 5–8 give the world position with the crater's height map, the predictor gives the
desired position, the safety guard the setpoint, and the sim's crane model (4 Hz sampling,
0.5 s reaction, velocity and acceleration limits) moves. The crane-to-robot error is sampled
at 20 Hz.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from common.markers import closest, detect, warm_up
from services.gantry.cycle import AFTER_REPORT_S, CycleSync
from services.gantry.locate import TrackingOptics, locate
from services.gantry.predict import AlgorithmName, make_predictor, prediction_horizon
from services.gantry.safety import SetpointGuard, Workspace
from services.sim.crane import CONTROL_ENABLE
from services.sim.lab import Lab, load_or_make_crater
from services.sim.robots import MARKER_HEIGHT_MM, SAMPLE_HZ, Trajectory
from services.sim.settings import SimSettings, TrackingCameraSettings

CONTROL_PERIOD_S = 0.25
ERROR_SAMPLE_S = 0.05
NOISE_FRAMES = 8
POLL_S = 0.025  # the gantry reads the controller's reported position at 40 Hz
START_S = 0.2
"""The gantry's first poll and tick: out of step with the controller's cycle (which starts at
0) — its ticks run free until the crane moves and ``CycleSync`` learns when it reports."""


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


def read_trajectory(path: Path, lab: Lab, marker_height_mm: float) -> Trajectory:
    """A robot path from CSV ``t,x,y`` (s, mm); z follows the crater plus the marker height."""
    try:
        data = np.genfromtxt(path, delimiter=",", names=True)
    except (OSError, ValueError) as err:
        raise ValueError(f"cannot read {path}: {err}") from err
    if data.dtype.names is None or not {"t", "x", "y"} <= set(data.dtype.names):
        raise ValueError(f"{path}: header must be t,x,y (got {data.dtype.names})")
    t, x, y = (np.atleast_1d(data[n]).astype(float) for n in ("t", "x", "y"))
    if len(t) < 2 or not np.all(np.isfinite([t, x, y])) or np.any(np.diff(t) <= 0):
        raise ValueError(f"{path}: needs ≥ 2 rows of finite numbers with increasing t")
    grid = np.arange(t[0], t[-1], 1 / SAMPLE_HZ)
    gx, gy = np.interp(grid, t, x), np.interp(grid, t, y)
    z = lab.crater.height_at(gx, gy) + marker_height_mm
    return Trajectory(path.stem, grid - grid[0], np.column_stack([gx, gy, z]))


def make_lab(scenario: str, seed: int, crater_file: Path) -> Lab:
    """The sim's lab for one run. A missing height map is made from the sim's own default seed,
    not the run's: every ``--seed`` runs in the same crater, whichever ran first."""
    crater = load_or_make_crater(SimSettings(crater_file=crater_file))
    settings = SimSettings(scenario=scenario, seed=seed, loop=False, crater_file=crater_file,
                           tracking_camera=TrackingCameraSettings(noise=0.0))
    return Lab.build(settings, crater)


def run(lab: Lab, algorithm: AlgorithmName, *, marker_height_mm: float, seed: int = 0,
        end_s: float | None = None) -> Run:
    """One experiment; ``lab`` is used up (its crane moves)."""
    warm_up()  # load the compiled detector before the clock starts
    started = time.perf_counter()
    cam = lab.tracking
    optics = TrackingOptics(cam.focal_mm, cam.pixel_mm, cam.ref_u, cam.ref_v, cam.height_mm)
    c = lab.settings.crane
    workspace = Workspace(c.x_min_mm, c.x_max_mm, c.y_min_mm, c.y_max_mm)
    guard = SetpointGuard(workspace, max_speed_mm_s=0.95 * c.max_speed_mm_s,
                          max_accel_mm_s2=0.95 * c.max_accel_mm_s2)
    predictor = make_predictor(algorithm, seed=seed,
                               horizon_s=prediction_horizon(c.reaction_s, CONTROL_PERIOD_S))
    noise_rng = np.random.default_rng((seed, 1))
    noise = noise_rng.normal(0.0, 2.5, (NOISE_FRAMES, cam.height_px, cam.width_px)
                             ).astype(np.float32)
    pixels = np.empty((cam.height_px, cam.width_px), np.float32)  # reused: no 1 MB per tick
    render_rng = np.random.default_rng((seed, 2))
    crane = lab.crane
    crane.write_control(0.0, CONTROL_ENABLE)
    end = lab.trajectory.duration_s if end_s is None else end_s
    result = Run(algorithm, np.array([]), np.zeros((0, 2)))
    samples_t, errors = [], []
    last_pixel: tuple[float, float] | None = None
    heartbeat = 0
    next_error = 0.0
    sync = CycleSync(CONTROL_PERIOD_S, AFTER_REPORT_S)
    for poll in range(int((end - START_S) / POLL_S) + 1):
        t = START_S + poll * POLL_S
        while next_error < t:  # error samples between polls
            samples_t.append(next_error)
            errors.append(lab.crane_state(next_error)[0] - lab.robot(next_error)[:2])
            next_error += ERROR_SAMPLE_S
        lab.crane_state(t)
        crane_xy = lab.crane.reported.copy()  # what its controller reports (≤ 1 cycle old)
        sync.observe(t, (round(crane_xy[0]), round(crane_xy[1])))  # registers: whole mm
        if not sync.due(t):
            continue
        result.report_age_s.append(t - lab.crane.reported_s)
        np.add(lab.tracking_frame(t, render_rng), noise[result.ticks % NOISE_FRAMES],
               out=pixels)
        image = np.clip(np.rint(pixels, out=pixels), 0, 255, out=pixels).astype(np.uint8)
        measured, last_pixel = _measure(image, last_pixel, crane_xy, optics, lab,
                                        marker_height_mm)
        estimate = predictor.update(t, measured)
        decision = guard.decide(t, None if estimate is None else estimate.desired,
                                t if estimate is not None else None, crane_xy)
        if estimate is not None:
            result.velocity_t_s.append(t)
            result.velocity_mm_s.append(estimate.velocity)
        result.held += decision.hold
        result.ticks += 1
        crane.write_setpoint(t, *decision.setpoint)
        heartbeat = (heartbeat + 1) % 65536
        crane.write_heartbeat(t, heartbeat)
    result.t_s, result.error_mm = np.array(samples_t), np.array(errors).reshape(-1, 2)
    result.wall_s = time.perf_counter() - started
    return result


def _measure(image: np.ndarray, last_pixel: tuple[float, float] | None, crane_xy: np.ndarray,
             optics: TrackingOptics, lab: Lab, marker_height_mm: float
             ) -> tuple[np.ndarray | None, tuple[float, float] | None]:
    found = detect(image, max_markers=20)
    if found.status == "none" or not found.markers:
        return None, last_pixel
    ref = last_pixel or (optics.ref_u, optics.ref_v)
    marker = closest(found.markers, *ref)
    if marker is None:
        return None, last_pixel
    xyz = locate(marker.u, marker.v, crane_xy, optics, lab.crater, marker_height_mm)
    return xyz[:2], (marker.u, marker.v)


def run_scenario(scenario: str, algorithm: AlgorithmName, *, seed: int, crater_file: Path,
                 trajectory_csv: Path | None = None) -> Run:
    lab = make_lab("locomotive" if trajectory_csv else scenario, seed, crater_file)
    height = MARKER_HEIGHT_MM.get(scenario, MARKER_HEIGHT_MM["locomotive"])
    if trajectory_csv is not None:
        lab.trajectory = read_trajectory(trajectory_csv, lab, height)
        lab.crane.place(*lab.trajectory.position(0.0)[:2])
    return run(lab, algorithm, marker_height_mm=height, seed=seed)
