"""The simulated lab's state: crater, robot, markers, PTZ heads, crane, tracking camera.

Everything is a function of the scenario time ``t`` (seconds since the sim started) and the
seed, so the live servers (real time) and fast experiments (simulated time) see the same lab.
"""

from __future__ import annotations

import functools
import logging
import math
import threading
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from common.camera import rot_z
from common.crane_frame import CraneFrame
from common.tracking_camera import TrackingCameraModel
from services.sim.bodies import (
    ROBOT_POINTS_MM,
    WAND_POINTS_MM,
    BodyDefinition,
    fit,
    heading_rad,
    place,
)
from services.sim.crane import CraneModel
from services.sim.mocap_server import MocapFrame
from services.sim.ptz import PtzHead
from services.sim.render import (
    MARKER_RADIUS_MM,
    Blob,
    Glint,
    NoiseBank,
    draw,
)
from services.sim.robots import Trajectory, railway_keep_clear, wand_point
from services.sim.settings import SimSettings
from services.sim.trajectories import make_trajectory
from services.sim.wand import View, WandCarrier
from services.sim.world import CraterMap, CraterShape, generate_crater

log = logging.getLogger(__name__)

LOOP_PAUSE_S = 5.0
WAND_LABEL = "wand"
"""The calibration marker on a pole: its own labelled marker, moving while the robot waits."""
OCCLUSION_WINDOW_S = 2.0


@functools.lru_cache(maxsize=8)
def _occlusion_start(seed: int, window: int) -> float | None:
    """When in its ``OCCLUSION_WINDOW_S`` window the robot's marker is hidden for 0.3 s (one
    window in twenty), or None; the same for every frame of the window (at 1000 Hz a generator
    made per frame cost as much as the frame's markers)."""
    rng = np.random.default_rng((seed, 7, window))
    if rng.random() >= 0.05:
        return None
    return float(rng.uniform(0, OCCLUSION_WINDOW_S - 0.3))


def load_or_make_crater(settings: SimSettings) -> CraterMap:
    """The crater file if it exists (as a real lab's laser scan would), else a new one saved
    there, generated from the seed."""
    path = settings.crater_file
    if path.exists():
        return CraterMap.load(path)
    crater = generate_crater(CraterShape(keep_clear=railway_keep_clear()),
                             np.random.default_rng(settings.seed))
    crater.save(path)
    log.info("generated crater height map %s (seed %d)", path, settings.seed)
    return crater


def calibration_views(heads: dict[str, PtzHead], t: float) -> list[View]:
    """The cameras a person carrying the wand waves it for at ``t``: those in calibration mode
    (IR-cut filter off, standing still), each seen through its own lens at its zoom."""
    views = []
    for head in heads.values():
        if head.ir_cut_filter == "off" and not head.state(t)[3]:
            views.append((head.pose(t), head.intrinsics(t)))
    return views


@dataclass
class Lab:
    settings: SimSettings
    crater: CraterMap
    trajectory: Trajectory
    static_markers: np.ndarray  # (S, 3)
    targets: np.ndarray  # (T, 3): commissioning targets standing below the crane
    ghost_markers: np.ndarray  # (G, 3)
    ptz_glints: list[Glint]
    ground_glints: list[Glint]
    heads: dict[str, PtzHead]
    crane: CraneModel
    crane_lock: threading.Lock
    tracking: TrackingCameraModel
    wand: WandCarrier
    noise: NoiseBank
    robot_start_s: float | None = 0.0
    """Sim time the robot's scenario starts; None: the robot waits at its start while the
    calibration wand is carried through the cameras' view."""
    wand_feed: Callable[[float], np.ndarray | None] | None = None
    """Where the wand is at a sim time, for a lab whose wand is carried elsewhere (the QTM
    process's: the carrier watches the cameras, which live in the sim's own process)."""
    crane_feed: Callable[[float], np.ndarray] | None = None
    """Where the crane's reported point is in the world at a sim time, for a lab whose crane
    model runs elsewhere (the QTM process's); None: this lab's own crane."""

    @classmethod
    def build(cls, settings: SimSettings, crater: CraterMap | None = None) -> Lab:
        crater = crater if crater is not None else load_or_make_crater(settings)
        rng = np.random.default_rng(settings.seed)
        trajectory = make_trajectory(settings.scenario, crater, rng,
                                     railway=settings.locomotive.railway(),
                                     walk=settings.walker.walk())
        heads = {cam.name: cam.head() for cam in settings.cameras}
        wand_rng = np.random.default_rng((settings.seed, 11))
        wand = WandCarrier(wand_rng, lambda r: wand_point(crater, r),
                           lambda t: calibration_views(heads, t),
                           lambda x, y: float(crater.height_at(x, y)),
                           start_mm=wand_point(crater, wand_rng),
                           speed_mm_s=settings.wand_speed_mm_s, dwell_s=settings.wand_dwell_s)
        waiting = settings.scenario == "calibration" or bool(settings.calibrate_first)
        c = settings.crane
        crane = CraneModel(c.params(), np.random.default_rng((settings.seed, 13)))
        crane.place(*c.frame().to_crane(trajectory.position(0.0)[:2]))
        t = settings.tracking_camera
        area_m2 = (c.x_max_mm - c.x_min_mm) * (c.y_max_mm - c.y_min_mm) / 1e6
        return cls(
            settings=settings, crater=crater, trajectory=trajectory,
            static_markers=_on_ground(crater, rng, settings.mocap.static_markers, 2600, 3400),
            ghost_markers=_on_ground(crater, rng, settings.mocap.ghost_markers, 500, 2500),
            targets=np.array([[x, y, float(crater.height_at(x, y)) + h]
                              for x, y, h in settings.targets]).reshape(-1, 3),
            ptz_glints=_glints(crater, rng, 8, 2500.0),
            ground_glints=_glints(crater, rng, int(round(t.reflections_per_m2 * area_m2)),
                                  max(c.x_max_mm, c.y_max_mm, -c.x_min_mm, -c.y_min_mm)),
            heads=heads,
            crane=crane, crane_lock=threading.Lock(),
            tracking=t.lens(),
            wand=wand, noise=NoiseBank(t.noise, t.width_px, t.height_px,
                                       np.random.default_rng((settings.seed, 17))),
            robot_start_s=None if waiting else 0.0)

    # --- the robot ---------------------------------------------------------------------------

    def scenario_time(self, t: float) -> float:
        if self.robot_start_s is None:
            return 0.0
        t = max(t - self.robot_start_s, 0.0)
        if not self.settings.loop:
            return t
        return t % (self.trajectory.duration_s + LOOP_PAUSE_S)

    def start_robot(self, t: float) -> None:
        """End the calibration phase: the wand leaves, the robot's scenario starts at ``t``."""
        if self.robot_start_s is None:
            self.robot_start_s = t
            log.info("calibration phase over at t = %.1f s: %s starts", t, self.trajectory.name)

    def robot(self, t: float) -> np.ndarray:
        """The robot marker's true world position (mm) at sim time ``t``."""
        return self.trajectory.position(self.scenario_time(t))

    def robot_velocity(self, t: float) -> np.ndarray:
        if self.robot_start_s is None or t < self.robot_start_s:
            return np.zeros(3)
        return self.trajectory.velocity(self.scenario_time(t))

    def robot_heading(self, t: float, marker: np.ndarray) -> float:
        """Where the robot (its marker at ``marker`` at ``t``) faces, radians."""
        return heading_rad(self.robot_velocity(t), self.robot(t + 0.5) - marker)

    def robot_pose(self, t: float) -> tuple[np.ndarray, float, float]:
        """(marker position, heading in radians, ground height under it) at ``t``: what a
        camera's picture draws of the robot."""
        marker = self.robot(t)
        return (marker, self.robot_heading(t, marker),
                float(self.crater.height_at(marker[0], marker[1])))

    def wand_position(self, t: float) -> np.ndarray | None:
        """The calibration wand's marker while the robot waits, else None."""
        if self.robot_start_s is not None and t >= self.robot_start_s:
            return None
        if self.wand_feed is not None:
            return self.wand_feed(t)
        return self.wand.position(t)

    def bright_points(self, t: float) -> np.ndarray:
        """Every IR marker a PTZ camera can see at ``t``: robot, wand and static ones."""
        wand = self.wand_position(t)
        extra = [] if wand is None else [wand[None, :]]
        return np.vstack([self.robot(t)[None, :], *extra, self.static_markers])

    # --- motion capture -----------------------------------------------------------------------

    @property
    def bodies(self) -> list[BodyDefinition]:
        """The 6DOF bodies QTM streams, in its order: the robot's, then the wand's."""
        m = self.settings.mocap
        return [BodyDefinition(name, points) for name, points in
                ((m.robot_body, ROBOT_POINTS_MM), (m.wand_body, WAND_POINTS_MM)) if name]

    @property
    def body_points(self) -> list[tuple[BodyDefinition, list[str]]]:
        """Each body with its points' labels (QTM's 6D parameters)."""
        m = self.settings.mocap
        origin = {m.robot_body: m.robot_label, m.wand_body: WAND_LABEL}
        return [(body, body.marker_labels(origin[body.name] or f"{body.name} - 1"))
                for body in self.bodies]

    @property
    def labels(self) -> list[str]:
        """QTM's 3D labels: the robot's marker, the wand's, the static ones, the crane's,
        then the bodies' other markers."""
        m = self.settings.mocap
        robot = [m.robot_label] if m.robot_label else []
        crane = [m.crane_label] if m.crane_label else []
        extra = [label for body in self.bodies for label in body.marker_labels("")[1:]]
        return (robot + [WAND_LABEL] + [f"static_{i + 1}" for i in range(len(self.static_markers))]
                + crane + [f"target_{i + 1}" for i in range(len(self.targets))] + extra)

    def crane_marker(self, t: float) -> np.ndarray:
        """The motion capture's ``crane`` marker at ``t``: on the carriage, at the crane's
        reported point and the tracking camera lens's height."""
        xy = self.crane_feed(t) if self.crane_feed is not None else self.crane_world_at(t)
        return np.array([xy[0], xy[1], self.tracking.height_mm])

    def mocap_frame(self, number: int) -> MocapFrame:
        """Frame ``number`` as QTM would measure it: noise, dropouts, occlusions, and the
        bodies fitted to the markers it saw."""
        m = self.settings.mocap
        t = number / m.rate_hz
        rng = np.random.default_rng((self.settings.seed, number))
        true_robot = self.robot(t)
        occluded = self._occluded(t)
        robot = np.full(3, np.nan) if occluded else true_robot
        wand = self.wand_position(t)
        wand = np.full(3, np.nan) if wand is None else wand
        crane = [self.crane_marker(t)[None, :]] if m.crane_label else []
        noisy = np.vstack([robot[None, :], wand[None, :], self.static_markers, *crane,
                           self.targets])
        noisy = noisy + rng.normal(0.0, m.noise_mm, size=noisy.shape)
        noisy[rng.random(len(noisy)) < m.dropout] = np.nan
        unlabelled = [(100 + i, xyz) for i, xyz in enumerate(self.ghost_markers)
                      if rng.random() < 0.5]
        origins = {m.robot_body: noisy[0], m.wand_body: noisy[1]}
        extra, bodies = self._body_markers(t, number, occluded, origins, true_robot)
        if m.robot_label:
            labelled = np.vstack([noisy, *extra]) if extra else noisy
        else:
            labelled = np.vstack([noisy[1:], *extra]) if extra else noisy[1:]
            if np.all(np.isfinite(noisy[0])):
                unlabelled.insert(0, (1, noisy[0]))
        return MocapFrame(number, int(round(t * 1e6)), labelled, unlabelled, bodies)

    def _body_markers(self, t: float, number: int, occluded: bool,
                      origins: dict[str, np.ndarray], robot: np.ndarray
                      ) -> tuple[list[np.ndarray], list[tuple[np.ndarray, np.ndarray] | None]]:
        """Each body's other markers as measured (noise and dropouts from a stream of their
        own, so the other markers' are as before), and its fitted pose (None: lost)."""
        m = self.settings.mocap
        rng = np.random.default_rng((self.settings.seed, number, 6))
        extra, poses = [], []
        for body in self.bodies:
            true = self._body_pose(body.name, t, robot)
            if true is None or (occluded and body.name == m.robot_body):
                points = np.full(body.points_mm.shape, np.nan)
            else:
                points = place(body.points_mm, *true)
                points[1:] += rng.normal(0.0, m.noise_mm, size=points[1:].shape)
                points[1:][rng.random(len(points) - 1) < m.dropout] = np.nan
            points[0] = origins[body.name]
            extra.append(points[1:])
            poses.append(fit(body.points_mm, points))
        return extra, poses

    def _body_pose(self, name: str, t: float, robot: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray] | None:
        """A body's true pose at ``t``; ``robot``: the robot's marker at ``t``."""
        if name == self.settings.mocap.robot_body:
            return robot, rot_z(self.robot_heading(t, robot))
        wand = self.wand_position(t)
        return None if wand is None else (wand, np.eye(3))

    def _occluded(self, t: float) -> bool:
        window = int(t // OCCLUSION_WINDOW_S)
        start = _occlusion_start(self.settings.seed, window)
        return start is not None and start <= t - window * OCCLUSION_WINDOW_S < start + 0.3

    # --- crane and its tracking camera ---------------------------------------------------------
    # The crane model runs in the crane's own frame (its registers, its travel); what the lab
    # shows of it (truth, the motion capture's crane marker, the camera's pictures) is in the
    # world's.

    @functools.cached_property
    def crane_frame(self) -> CraneFrame:
        return self.settings.crane.frame()

    def place_crane(self, xy_world: np.ndarray) -> None:
        """The crane at rest over a world point (at start, and in experiments)."""
        with self.crane_lock:
            self.crane.place(*self.crane_frame.to_crane(xy_world[:2]))

    def crane_state(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(position, velocity) of the crane's reference point at ``t`` in the world (mm,
        mm/s): from its history where another thread has advanced it past ``t`` already (a
        thread that read the clock, then waited for the lock, would take a later state for
        ``t``)."""
        with self.crane_lock:
            self.crane.advance_to(t)
            position, velocity = self.crane.state_at(t)
        return self.crane_frame.to_world(position), self.crane_frame.vector_to_world(velocity)

    def crane_world_at(self, t: float) -> np.ndarray:
        """Where the crane's reference point was at ``t`` (recent), in the world."""
        with self.crane_lock:
            return self.crane_frame.to_world(self.crane.position_at(t))

    def newest_capture(self, now: float) -> tuple[int, float]:
        """The newest tracking frame that has arrived by ``now`` (frames are taken at the
        camera's rate and arrive ``delay_s`` after their exposure): its number and the time
        its exposure ended."""
        cam = self.settings.tracking_camera
        number = math.floor((now - cam.delay_s) * cam.rate_hz + 1e-9)
        return number, number / cam.rate_hz

    def tracking_frame(self, t: float, rng: np.random.Generator) -> np.ndarray:
        """The downward tracking camera's frame whose exposure ends at ``t`` (uint8, height ×
        width), through the camera's own lens and mount (``[sim.tracking_camera]``): everything
        that moves relative to the crane smears over the exposure. The crane must have been
        advanced to ``t`` or later (``crane_state``)."""
        cam, exposure = self.tracking, self.settings.tracking_camera.exposure_s
        frame = self.crane_frame
        crane, crane_before = self.crane_world_at(t), self.crane_world_at(t - exposure)
        targets, glints = len(self.targets), self._glint_points
        # the robot as it was when the exposure began, seen from where the crane was then: the
        # same pixel as the robot moved by the crane's travel since, seen from where it is now
        before = self.robot(t - exposure).copy()
        before[:2] += crane - crane_before
        pixels, scales = cam.project(np.vstack([self.robot(t), self.targets, glints, before]),
                                     crane, frame)
        now, before = pixels[0], pixels[-1]
        pixels, scales = pixels[:-1], scales[:-1]
        lit = self.settings.tracking_camera
        ms = exposure * 1000.0  # below saturation a sensor's gray level is linear in exposure
        marker = min(lit.marker_gray_per_ms * ms, 255.0)
        blobs = [Blob(now[0], now[1], MARKER_RADIUS_MM * scales[0], MARKER_RADIUS_MM * scales[0],
                      peak=marker, smear_u=now[0] - before[0], smear_v=now[1] - before[1])]
        blobs += [Blob(u, v, MARKER_RADIUS_MM * k, MARKER_RADIUS_MM * k, peak=marker)
                  for (u, v), k in zip(pixels[1:1 + targets], scales[1:1 + targets], strict=True)
                  if -20 < u < cam.width_px + 20 and -20 < v < cam.height_px + 20]
        glint = min(lit.glint_gray_per_ms * ms, 255.0)
        for g, (gu, gv), k in zip(self.ground_glints, pixels[1 + targets:],
                                  scales[1 + targets:], strict=True):
            if -50 < gu < cam.width_px + 50 and -50 < gv < cam.height_px + 50:
                blobs.append(Blob(gu, gv, max(g.long_mm * k, 1.5), max(g.short_mm * k, 0.6),
                                  g.angle_rad, glint))
        return draw(blobs, cam.width_px, cam.height_px, rng,
                    background=min(lit.ground_gray_per_ms * ms, 255.0), noise=self.noise)

    @functools.cached_property
    def _glint_points(self) -> np.ndarray:
        """The ground glints' points (N, 3)."""
        return np.array([[g.x_mm, g.y_mm, g.z_mm] for g in self.ground_glints]).reshape(-1, 3)


def _on_ground(crater: CraterMap, rng: np.random.Generator, count: int, r_min: float,
               r_max: float) -> np.ndarray:
    r = rng.uniform(r_min, r_max, count)
    a = rng.uniform(0, 2 * np.pi, count)
    x, y = r * np.cos(a), r * np.sin(a)
    return np.column_stack([x, y, crater.height_at(x, y) + 20.0]) if count else np.zeros((0, 3))


def _glints(crater: CraterMap, rng: np.random.Generator, count: int, half: float
            ) -> list[Glint]:
    out = []
    for _ in range(count):
        x, y = rng.uniform(-half, half, 2)
        out.append(Glint(float(x), float(y), float(crater.height_at(x, y)) + 5.0,
                         float(rng.uniform(25, 45)), float(rng.uniform(5, 10)),
                         float(rng.uniform(0, np.pi))))
    return out
