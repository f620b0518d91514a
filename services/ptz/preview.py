"""Preview snapshots of a following camera, for the operator's page and recordings.

A thread of its own with its own HTTP client, so that a slow snapshot never delays a move
command. Each preview carries the markers the detector finds and the pixel where the tracked
robot marker should be (the robot's position projected through the camera's calibrated pose
at the pan and tilt it reports right after the snapshot).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable

import numpy as np

from common import messages as m
from common.camera import Intrinsics, Pose, head_pose, project_camera
from common.lab_views import PAPER_MARKER_MM
from common.markers import detect, to_message
from common.ptz_lens import PtzLens
from services.ptz.aim import predict
from services.ptz.camera import PtzCamera, PtzError, decode_jpeg

log = logging.getLogger(__name__)


def robot_view(mount: Pose | None, robot: m.RobotPosition | None, pan_deg: float,
               tilt_deg: float, intr: Intrinsics, at_s: float,
               marker_diameter_mm: float = PAPER_MARKER_MM
               ) -> tuple[list[float] | None, float | None]:
    """Where the robot marker appears in an image taken at ``at_s`` through the lens ``intr``
    (its focal length at the image's zoom, its distortion) and how large (radius, px), from
    one prediction (pure); (None, None) without a pose or a robot, or when it is behind the
    camera."""
    if mount is None or robot is None:
        return None, None
    in_camera = head_pose(mount, pan_deg, tilt_deg).to_camera(_robot_at(robot, at_s)[None, :])
    u, v = project_camera(in_camera, intr)[0]
    if not (np.isfinite(u) and np.isfinite(v)):  # behind the camera
        return None, None
    radius = intr.fy_px * marker_diameter_mm / 2 / in_camera[0, 0]
    return [round(float(u), 1), round(float(v), 1)], round(float(radius), 2)


def _robot_at(robot: m.RobotPosition, at_s: float) -> np.ndarray:
    """The robot marker predicted to ``at_s`` from its sample (at most 1 s ahead)."""
    return predict(np.array([robot.x_mm, robot.y_mm, robot.z_mm]),
                   np.array([robot.vx_mm_s, robot.vy_mm_s, robot.vz_mm_s]),
                   at_s - robot.measured_s, max_ahead_s=1.0)


class PreviewLoop:
    """Takes a preview every ``period_s`` unless ``paused()`` (calibration mode owns the
    camera then); camera errors are logged once per outage and retried next period."""

    def __init__(self, camera: PtzCamera, period_s: float,
                 publish: Callable[[m.PtzPreview, Intrinsics, bool], None],
                 mount: Callable[[], Pose | None], robot: Callable[[], m.RobotPosition | None],
                 lens: Callable[[], PtzLens],
                 paused: Callable[[], bool], stop: threading.Event,
                 infrared: Callable[[float], bool] = lambda _now: False,
                 marker_diameter_mm: float = PAPER_MARKER_MM,
                 clock: Callable[[], float] = time.time) -> None:
        """``publish(preview, intrinsics, infrared)``: the preview, the lens it was taken
        through (``lens()`` at its zoom), and whether the IR-cut filter was off for it (the
        markers bright). When ``infrared(now)`` says so (the pointing check's schedule:
        ``PtzControl.infrared_due``) a preview is taken with the filter off, and the filter is
        set back to auto right after. ``marker_diameter_mm``: the robot marker's, for how
        large it should appear. ``clock``: the capture times' (wall time)."""
        self.camera, self.period_s, self.publish = camera, period_s, publish
        self.infrared = infrared
        self.marker_diameter_mm = marker_diameter_mm
        self.mount, self.robot, self.paused, self.stop = mount, robot, paused, stop
        self.lens, self.clock = lens, clock
        self._seq = 0
        self._failing = False
        self._thread = threading.Thread(target=self._run, name="ptz-preview", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def join(self, timeout: float) -> None:
        if self._thread.is_alive():
            self._thread.join(timeout)

    def _run(self) -> None:
        while not self.stop.wait(self.period_s):
            self.once()

    def once(self) -> None:
        """One period's preview, unless paused; a camera error is logged once per outage."""
        if self.paused():
            return
        try:
            self.publish(*self._take_maybe_in_infrared())
            if self._failing:
                log.info("%s: previews again", self.camera.name)
            self._failing = False
        except PtzError as err:
            if not self._failing:
                log.warning("%s: no preview: %s", self.camera.name, err)
            self._failing = True

    def _take_maybe_in_infrared(self) -> tuple[m.PtzPreview, Intrinsics, bool]:
        if not self.infrared(self.clock()):
            return *self.take(), False
        self.camera.set_ir_cut_filter("off")
        try:
            return *self.take(), True
        finally:
            if not self.paused():  # calibration mode keeps the filter off (it says so again)
                self.camera.set_ir_cut_filter("auto")

    def take(self) -> tuple[m.PtzPreview, Intrinsics]:
        captured = self.clock()
        jpeg = self.camera.snapshot_jpeg()
        position = self.camera.position()
        image = decode_jpeg(jpeg, self.camera.name)
        height, width = image.shape
        found = to_message(detect(image, max_markers=8), self.camera.name, captured, width,
                           height)
        self._seq += 1
        intr = self.lens().intrinsics(position.zoom, width, height)
        robot_px, radius_px = robot_view(self.mount(), self.robot(), position.pan_deg,
                                         position.tilt_deg, intr, captured,
                                         self.marker_diameter_mm)
        return m.PtzPreview(
            measured_s=captured, camera=self.camera.name, seq=self._seq, width_px=width,
            height_px=height, jpeg=jpeg, pan_deg=min(max(position.pan_deg, -180.0), 180.0),
            tilt_deg=min(max(position.tilt_deg, -90.0), 90.0), markers=found.markers,
            robot_px=robot_px, robot_radius_px=radius_px
        ), intr
