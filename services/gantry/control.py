"""One control step of the gantry (paper §3; pure): the newest tracking frame and the crane's
reported position in, a safe setpoint out.

detect (§2.1) → pick the marker (the one closest to the last, §3.1) → locate (eq. 5–8, with the
crater's height map) → predict (eq. 9–12 or ``default``) → guard (workspace, limits, stale
hold). The live service and the experiments call the same ``Controller``; neither repeats any
of these steps.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from common.heightmap import HeightMap
from common.markers import Detection, closest, detect
from services.gantry.frames import Frame
from services.gantry.locate import TrackingOptics, locate
from services.gantry.predict import Estimate, make_predictor, prediction_horizon
from services.gantry.safety import SetpointGuard, Workspace
from services.gantry.settings import GantrySettings

MAX_MARKERS = 20


@dataclass(frozen=True)
class Step:
    """What one control step saw, believed and decided."""

    setpoint: np.ndarray  # (x, y) mm: what to send the crane, always inside the workspace
    hold: bool
    reason: str  # why it holds; "" when tracking
    frame_s: float | None = None  # capture time of the frame used (None: no new frame)
    frame_shape: tuple[int, int] = (0, 0)  # its (height, width) in pixels
    detection: Detection | None = None
    measured_xyz: np.ndarray | None = None  # the robot's marker in the world (eq. 8)
    estimate: Estimate | None = None
    estimate_s: float | None = None  # capture time of the frame the estimate rests on


class Controller:
    """The gantry's control law with the state that belongs to it: the last marker pixel, the
    predictor's filters, the estimate and its age, the guard's last setpoint."""

    def __init__(self, settings: GantrySettings, heights: HeightMap) -> None:
        s = settings
        self.settings, self.heights = s, heights
        self.optics = TrackingOptics(s.focal_mm, s.pixel_mm, s.ref_u, s.ref_v,
                                     s.lens_height_mm)
        self.predictor = make_predictor(s.algorithm, seed=s.seed, horizon_s=min(
            prediction_horizon(s.reaction_s, 1 / s.control_hz), s.max_horizon_s),
            particle=s.particle_filter.options())
        self.guard = SetpointGuard(
            Workspace(s.x_min_mm, s.x_max_mm, s.y_min_mm, s.y_max_mm, s.workspace_margin_mm),
            s.max_speed_mm_s, s.max_accel_mm_s2, s.stale_after_s)
        self.estimate: Estimate | None = None
        self.estimate_s: float | None = None
        self.last_pixel: tuple[float, float] | None = None

    def restart(self) -> None:
        """The crane stopped on its own (watchdog, link loss, disabled): the next setpoint
        starts from where it stands."""
        self.guard.reset()

    def step(self, now_s: float, frame: Frame | None, crane_xy: np.ndarray) -> Step:
        """One control period: ``frame`` is the newest frame not used yet (or None),
        ``crane_xy`` the crane's position as its controller reports it (mm)."""
        crane_xy = np.asarray(crane_xy, dtype=float)
        seen: dict = {}
        if frame is not None:
            seen = self._measure(frame, crane_xy)
        decision = self.guard.decide(now_s, None if self.estimate is None else
                                     self.estimate.desired, self.estimate_s, crane_xy)
        return Step(decision.setpoint, decision.hold, decision.reason,
                    estimate=self.estimate, estimate_s=self.estimate_s, **seen)

    def _measure(self, frame: Frame, crane_xy: np.ndarray) -> dict:
        captured, image = frame
        found = detect(image, max_markers=MAX_MARKERS)
        xyz = self._locate(found, crane_xy)
        self.estimate = self.predictor.update(captured, None if xyz is None else xyz[:2])
        self.estimate_s = captured if self.estimate is not None else None
        return {"frame_s": captured, "frame_shape": image.shape, "detection": found,
                "measured_xyz": xyz}

    def _locate(self, found: Detection, crane_xy: np.ndarray) -> np.ndarray | None:
        if not found.markers:
            return None
        ref = self.last_pixel or (self.optics.ref_u, self.optics.ref_v)
        marker = closest(found.markers, *ref)
        if marker is None:
            return None
        self.last_pixel = (marker.u, marker.v)
        return locate(marker.u, marker.v, crane_xy, self.optics, self.heights,
                      self.settings.marker_height_mm)
