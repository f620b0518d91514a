"""The crane's observation camera (paper §3.1: "an observation camera is used for data
acquisition and monitoring tasks", beside the tracking camera): a colour picture straight
down from the camera carriage, moving with the crane — the crater around the robot, the
robot's body, its six legs stepping, and its marker (pure, apart from the clock it is given).

It hangs ``offset_mm`` from the crane's reported point (in the crane's frame), ``height_mm``
above the world's z = 0, its image's columns along the crane's x axis and its rows against the
crane's y axis (north up when the crane is aligned with the world). The picture is drawn
through the PTZ cameras' pinhole (``common.camera``: focal length, chip, resolution) and the
same ground renderer (``services.sim.scene``); nothing in the code models this camera — it is
for people (the page, recordings, reports) — so the sim's values are its only truth.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal

import cv2
import numpy as np

from common.camera import Intrinsics, Pose, project, rot_z
from common.crane_frame import CraneFrame
from services.sim.render import MARKER_RADIUS_MM
from services.sim.scene import ROBOT_GAP_MM, ROBOT_SIZE_MM, GroundView, chassis_outline

if TYPE_CHECKING:
    from services.sim.lab import Lab
    from services.sim.settings import SimSettings

REGOLITH_BGR = (150.0, 172.0, 188.0, 0.0)  # a grey, slightly warm ground
CHASSIS_BGR = (92, 70, 56)
LEG_BGR = (52, 44, 40)
MARKER_BGR = (250, 250, 250)
LEG_REACH_MM = 190.0  # a foot's distance out from the chassis' side
LEG_SWING_MM = 35.0  # a foot's swing forward and back over a step (a quarter of the legs' spacing)
STEP_HZ = 1.3  # the gait's cycles a second while the robot moves (the walker's default)
MOVING_MM_S = 5.0  # slower than this, the robot stands on its feet
NOISE = 3.0  # colour noise sigma, grey levels
NOISE_FIELDS = 4  # drawn once per picture size and cycled: a frame's worth of normal
                  # deviates costs 20 ms, and nobody watching can tell


@dataclass(frozen=True)
class ObservationView:
    """Where the camera hangs and what its chip is."""

    focal_mm: float
    chip_mm: tuple[float, float]
    offset_mm: tuple[float, float]
    height_mm: float

    def pose(self, crane_xy_world: np.ndarray, frame: CraneFrame) -> Pose:
        """The camera's pose when the crane's reported point is at ``crane_xy_world``: looking
        straight down (camera x), u along the crane's x axis, v against its y axis."""
        lens = np.asarray(crane_xy_world, float) + frame.vector_to_world(self.offset_mm)
        a = math.radians(frame.yaw_deg)
        rotation = np.column_stack([(0.0, 0.0, -1.0), (math.cos(a), math.sin(a), 0.0),
                                    (math.sin(a), -math.cos(a), 0.0)])
        return Pose.from_matrix(rotation, np.array([lens[0], lens[1], self.height_mm]))

    def intrinsics(self, width: int, height: int) -> Intrinsics:
        return Intrinsics.from_chip(self.focal_mm, self.chip_mm, width, height)


def legs_mm(marker_mm: np.ndarray, heading_rad: float, ground_mm: float, phase_rad: float
            ) -> list[tuple[np.ndarray, np.ndarray]]:
    """(hip, foot) world points of the robot's six legs: three a side, in two tripods that
    swing in turn."""
    length, width = ROBOT_SIZE_MM
    top = float(marker_mm[2]) - ROBOT_GAP_MM
    turn = rot_z(heading_rad)[:2, :2]
    legs = []
    for i, along in enumerate((-length / 3, 0.0, length / 3)):
        for side in (-1, 1):
            tripod = (i + (side > 0)) % 2
            swing = LEG_SWING_MM * math.sin(phase_rad + math.pi * tripod)
            hip = np.array([along, side * width / 2])
            foot = hip + np.array([swing, side * LEG_REACH_MM])
            legs.append((np.array([*(turn @ hip + marker_mm[:2]), top]),
                         np.array([*(turn @ foot + marker_mm[:2]), ground_mm])))
    return legs


@dataclass
class ObservationCamera:
    """One observation camera as ``services.sim.camera_server`` serves it (VAPIX pictures
    only): ``crane`` gives the crane's reported point in the world now, ``robot`` the robot's
    (marker, heading, ground height, speed mm/s) now."""

    name: str
    view: ObservationView
    ground: GroundView
    frame: CraneFrame
    crane: Callable[[float], np.ndarray]
    robot: Callable[[float], tuple[np.ndarray, float, float, float]]
    clock: Callable[[], float]
    rng: np.random.Generator
    user: str = "root"
    password: str = "pass"
    auth: Literal["digest", "basic", "none"] = "digest"
    jpeg_quality: int = 85
    mjpeg_fps: float = 10.0
    resolutions: dict[str, tuple[int, int]] = field(
        default_factory=lambda: {"640x480": (640, 480), "320x240": (320, 240)})
    _phase: float = 0.0
    _phase_at: float | None = None
    _noise: dict[tuple[int, int], list[np.ndarray]] = field(default_factory=dict)
    _pictures: int = 0

    def snapshot(self, width: int, height: int, waited_s: float = 0.0) -> np.ndarray:
        """The picture of when its request came, ``waited_s`` ago (BGR, uint8): its own
        process renders on idle time, the scene is not drawn later for that."""
        now = self.clock() - waited_s
        pose = self.view.pose(self.crane(now)[:2], self.frame)
        intr = self.view.intrinsics(width, height)
        image = cv2.multiply(cv2.cvtColor(self.ground.brightness(pose, intr),
                                          cv2.COLOR_GRAY2BGR), REGOLITH_BGR)
        marker, heading, ground, speed = self.robot(now)
        self._step(now, speed)
        for hip, foot in legs_mm(marker, heading, ground, self._phase):
            uv = project(np.vstack([hip, foot]), pose, intr)
            if np.all(np.isfinite(uv)):
                hip_px, foot_px = ((round(u * 16), round(v * 16)) for u, v in uv)
                cv2.line(image, hip_px, foot_px,
                         LEG_BGR, max(2, round(intr.fy_px * 25 / pose.z_mm)), cv2.LINE_AA,
                         shift=4)
        hull = chassis_outline(marker, heading, ground, pose, intr)
        if hull is not None:
            cv2.fillConvexPoly(image, hull, CHASSIS_BGR, lineType=cv2.LINE_AA, shift=4)
        dot = project(marker[None, :], pose, intr)[0]
        if np.all(np.isfinite(dot)):
            radius = MARKER_RADIUS_MM * intr.fy_px / max(pose.z_mm - marker[2], 1.0)
            cv2.circle(image, tuple(int(round(c * 16)) for c in dot), max(1, round(radius * 16)),
                       MARKER_BGR, -1, cv2.LINE_AA, shift=4)
        return cv2.add(image, self._noise_field(width, height), dtype=cv2.CV_8U)

    def _noise_field(self, width: int, height: int) -> np.ndarray:
        fields = self._noise.get((width, height))
        if fields is None:
            fields = self._noise[(width, height)] = [
                self.rng.normal(0.0, NOISE, (height, width, 3)).astype(np.float32)
                for _ in range(NOISE_FIELDS)]
        self._pictures += 1
        return fields[self._pictures % NOISE_FIELDS]

    def _step(self, now: float, speed_mm_s: float) -> None:
        """The gait goes on while the robot moves."""
        if self._phase_at is not None and speed_mm_s > MOVING_MM_S:
            self._phase += 2 * math.pi * STEP_HZ * max(0.0, now - self._phase_at)
        self._phase_at = now


def observation_camera(lab: Lab, settings: SimSettings, clock: Callable[[], float],
                       crane: Callable[[float], np.ndarray],
                       robot_started: Callable[[float], None] = lambda _t: None
                       ) -> ObservationCamera:
    """The lab's observation camera as ``[sim.observation_camera]`` sets it up: ``crane`` is
    where the crane's reported point is in the world at a sim time; ``robot_started(t)`` is
    asked before the robot is looked at (a process of its own learns the start that way)."""
    o = settings.observation_camera

    def robot(now: float) -> tuple[np.ndarray, float, float, float]:
        robot_started(now)
        return (*lab.robot_pose(now), float(np.linalg.norm(lab.robot_velocity(now)[:2])))

    return ObservationCamera(
        o.name, ObservationView(o.focal_mm, o.chip_mm, o.offset_mm, o.height_mm),
        GroundView.of(lab.crater, settings.seed), lab.crane_frame, crane, robot, clock,
        np.random.default_rng((settings.seed, 29)), o.user, o.password, o.auth,
        jpeg_quality=o.jpeg_quality, mjpeg_fps=o.mjpeg_fps)
