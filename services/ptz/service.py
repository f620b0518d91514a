"""PTZ service: points one AXIS camera at the tracked robot (paper §2.3).

Subscribes: stb/tracker/robot (RobotPosition), stb/calib/{camera}/pose (CameraPose; also
            queried at start for a pose published before this service ran)
            stb/ptz/{camera}/calibration (CalibrationMode: hold still and detect, with a lease)
Publishes:  stb/ptz/{camera}/state (PtzState: pan, tilt, zoom, status, aim error, and the
            pointing check's measured error from the previews), state_hz
            in calibration mode: stb/ptz/{camera}/detections and .../snapshot per snapshot
            otherwise stb/ptz/{camera}/preview (PtzPreview), preview_hz, for people to look at
Drives:     the camera over VAPIX (pan/tilt/zoom), at most command_hz, with a dead band;
            a move by someone else pauses following for manual_pause_s (status manual)
"""

from __future__ import annotations

import logging
import threading
import time

import numpy as np

from common import codec, keys
from common import messages as m
from common.camera import Pose, PtzLimits, focal_mm_for_zoom
from common.markers import warm_up
from common.node import Node
from services.ptz.aim import aim_error_deg
from services.ptz.calibration import CalibrationHold
from services.ptz.camera import AxisPtzCamera, PtzCamera, PtzError, http_client
from services.ptz.follow import Follower
from services.ptz.override import ManualOverride
from services.ptz.pointing import NOT_SEEN, PointingCheck
from services.ptz.preview import PreviewLoop
from services.ptz.settings import PtzSettings

log = logging.getLogger(__name__)
RETRY_MAX_S = 5.0


def make_camera(settings: PtzSettings) -> AxisPtzCamera:
    c = settings.connection()
    client = http_client(c.url, c.user, c.password.get_secret_value(), c.auth,
                         settings.timeout_s)
    return AxisPtzCamera(client, settings.instance)


def run(node: Node, camera: PtzCamera | None = None) -> None:
    settings: PtzSettings = node.settings  # type: ignore[assignment]
    log.info("detector ready (%.1f s)", warm_up())  # previews and calibration mode detect
    # Position queries have a client of their own, like previews: a query in flight never
    # holds up a move command (that client is the injected camera's in tests).
    loop = _Loop(node, settings, camera or make_camera(settings),
                 queries=camera or make_camera(settings))
    name = settings.instance
    node.bus.subscribe(keys.CALIB_POSE, loop.on_pose, latest=False, camera=name)
    for pose in node.bus.query_latest(keys.CALIB_POSE, timeout_s=1.0, camera=name):
        loop.on_pose(pose)
    node.bus.subscribe(keys.TRACKER_ROBOT, loop.on_robot)
    # latest wins: a burst of requests is not queued up to move the camera for seconds after
    node.bus.subscribe(keys.PTZ_CALIBRATION, loop.on_calibration, latest=True, camera=name)
    preview = None
    if settings.preview_hz > 0:
        preview = PreviewLoop(
            make_camera(settings), 1 / settings.preview_hz,  # its own client: never in the way
            loop.on_preview,
            mount=lambda: _pose(loop.pose), robot=lambda: loop.robot,
            paused=lambda: loop.calibration.active(time.time()), stop=node.stop,
            infrared_every_s=settings.pointing_infrared_s)
        preview.start()
    try:
        loop.run()
    finally:
        if preview is not None:
            preview.join(timeout=2 * settings.timeout_s)


class _Loop:
    """Commands go out as robot samples arrive (no polling delay); camera state is queried
    and published ``state_hz`` times a second. One lock serialises the commands and guards the
    loop's state; it is not held while the state query waits for the camera."""

    def __init__(self, node: Node, settings: PtzSettings, camera: PtzCamera,
                 queries: PtzCamera) -> None:
        self.node, self.settings, self.camera, self.queries = node, settings, camera, queries
        self.follower = Follower(deadband_deg=settings.deadband_deg,
                                 latency_s=settings.latency_s,
                                 min_interval_s=1 / settings.command_hz, zoom=settings.zoom,
                                 target_size_mm=settings.target_size_mm,
                                 image_fraction=settings.image_fraction)
        self.lock = threading.Lock()
        self.pose: m.CameraPose | None = None
        self.robot: m.RobotPosition | None = None
        self.limits: PtzLimits | None = None
        self.retry_at, self.retry_s = 0.0, 0.5
        name = settings.instance
        self.calibration = CalibrationHold(
            camera,
            lambda msg: node.bus.publish(keys.PTZ_DETECTIONS, msg, camera=name),
            lambda msg: node.bus.publish(keys.PTZ_SNAPSHOT, msg, camera=name),
            max_markers=settings.calibration_max_markers)
        self.state_due = 0.0
        self.pointing = PointingCheck(settings.pointing_tolerance_deg, settings.pointing_persist)
        self.override = ManualOverride(settings.manual_deg, settings.manual_pause_s)
        self.manual = False  # following paused for someone else's move

    def on_preview(self, preview: m.PtzPreview, focal_mm: float, infrared: bool) -> None:
        """Publish it, and judge from it how well the camera points (services/ptz/pointing)."""
        self.node.bus.publish(keys.PTZ_PREVIEW, preview, camera=self.settings.instance)
        with self.lock:
            self.pointing.observe(preview, focal_mm, infrared)

    def on_pose(self, msg: m.CameraPose) -> None:
        ahead_s = msg.measured_s - time.time()
        if ahead_s > self.settings.bus.max_future_s:  # one such pose used to win for good
            key = keys.CALIB_POSE.key(self.node.bus.prefix, camera=msg.camera)
            self.node.bus.count_drop(key, codec.FROM_FUTURE, f"pose measured {ahead_s:.0f} s "
                                     "in the future: refused")
            return
        with self.lock:
            # newer: a higher version from the calibration service, or the same one measured
            # later (the calibration service out-versions a pose on its key it did not send)
            if self.pose is None or _order(msg) >= _order(self.pose):
                log.info("camera pose received (fit error %.2f px)", msg.mean_error_px)
                if msg != self.pose:
                    self.pointing.forget()
                self.pose = msg

    def on_calibration(self, msg: m.CalibrationMode) -> None:
        with self.lock:
            now = time.time()
            try:
                self.calibration.on_request(msg, now, self.limits or PtzLimits())
            except PtzError as err:
                self._unreachable(now, err)
            if not self.calibration.active(now):
                self.follower.forget()

    def on_robot(self, msg: m.RobotPosition) -> None:
        with self.lock:
            self.robot = msg
            pose = _pose(self.pose)
            now = time.time()
            if (pose is None or self.limits is None or now < self.retry_at
                    or self.calibration.active(now) or self.override.paused(now)):
                return
            command = self.follower.command(now, _xyz(msg), _velocity(msg), msg.measured_s,
                                            pose)
            if command is None:
                return
            try:
                self.camera.move_to(command.pan_deg, command.tilt_deg, command.zoom,
                                    self.settings.speed, measured_s=command.measured_s)
                self.override.commanded(now, command.pan_deg, command.tilt_deg)
            except PtzError as err:
                self._unreachable(now, err)

    def run(self) -> None:
        state_period = 1 / self.settings.state_hz
        snapshot_period = 1 / self.settings.calibration_snapshot_hz
        period = state_period
        while not self.node.stop.wait(period):
            now = time.time()
            with self.lock:
                if now < self.retry_at:
                    continue
            try:
                with self.lock:
                    calibrating = self._calibration_step(now)
                if now >= self.state_due:
                    self.state_due = now + state_period
                    self._report(now)
                with self.lock:
                    self.retry_s = 0.5
            except PtzError as err:
                with self.lock:
                    self._unreachable(now, err)
                calibrating = False
            period = snapshot_period if calibrating else min(state_period,
                                                             max(self.state_due - now, 0.0))

    def _calibration_step(self, now: float) -> bool:
        """A calibration snapshot if the mode is on; leaves it when the lease ran out."""
        if self.calibration.request is None:
            return False
        if not self.calibration.active(now):
            self.calibration.leave()
            self.follower.forget()
            return False
        self.calibration.cycle()
        return True

    def _report(self, now: float) -> None:
        """Query the camera (without the lock) and publish its state."""
        if self.limits is None:
            limits = self.queries.limits()
            with self.lock:
                self.limits = self.follower.limits = limits
            log.info("camera %s limits: %s", self.camera.name, limits)
        position = self.queries.position()
        with self.lock:
            pose, robot = _pose(self.pose), self.robot
            calibrating = self.calibration.active(now)
            pointing_error, problem = self.pointing.error_deg, self.pointing.problem() or ""
            manual = self._watch_hands(now, position.pan_deg, position.tilt_deg, calibrating)
        status = "waiting_for_pose" if pose is None else ("tracking" if robot else "idle")
        if calibrating:
            status = "calibrating"
        elif manual:
            status = "manual"
        if pose is None:
            self.node.set_status("degraded", "waiting for a camera pose from calib")
        else:
            self.node.set_status("degraded" if problem else "ok", problem)
        error = 0.0
        if pose is not None and robot is not None:
            error = aim_error_deg(_xyz(robot), pose, position.pan_deg, position.tilt_deg)
        self._publish(status, position.pan_deg, position.tilt_deg, position.zoom, error, now,
                      pointing_error if pointing_error != NOT_SEEN else None, problem)

    def _watch_hands(self, now: float, pan: float, tilt: float, calibrating: bool) -> bool:
        """Whether following is paused for someone else's move (``self.lock`` held)."""
        if calibrating:  # calibration mode moves the camera itself; nothing to compare with
            self.override.forget()
            self.manual = False
            return False
        if self.override.observe(now, pan, tilt) and not self.manual:
            log.warning("%s: moved by someone else (now pan %.1f°, tilt %.1f°): following "
                        "paused for %g s", self.camera.name, pan, tilt,
                        self.settings.manual_pause_s)
        paused = self.override.paused(now)
        if self.manual and not paused:
            log.info("%s: following again after a manual move", self.camera.name)
            self.follower.forget()  # the next sample sends a fresh command
        self.manual = paused
        return paused

    def _publish(self, status: str, pan: float, tilt: float, zoom: int, error: float,
                 now: float, pointing_error: float | None = None, problem: str = "") -> None:
        self.node.bus.publish(keys.PTZ_STATE, m.PtzState(
            measured_s=now, camera=self.settings.instance, status=status,
            pan_deg=min(max(pan, -180.0), 180.0), tilt_deg=min(max(tilt, -90.0), 90.0),
            zoom=min(max(zoom, 1), 19999), focal_mm=focal_mm_for_zoom(zoom),
            aim_error_deg=error, pointing_error_deg=pointing_error, pointing_problem=problem),
            camera=self.settings.instance)

    def _unreachable(self, now: float, err: PtzError) -> None:
        self.node.set_status("degraded", str(err))
        self.retry_at, self.retry_s = now + self.retry_s, min(self.retry_s * 2, RETRY_MAX_S)
        self.limits = None  # ask again: the camera may have been replaced or reconfigured
        self._publish("camera_unreachable", 0.0, 0.0, 1, 0.0, now)


def _order(pose: m.CameraPose) -> tuple[int, float]:
    return pose.version, pose.measured_s


def _pose(msg: m.CameraPose | None) -> Pose | None:
    if msg is None:
        return None
    return Pose.of(msg)


def _xyz(robot: m.RobotPosition) -> np.ndarray:
    return np.array([robot.x_mm, robot.y_mm, robot.z_mm])


def _velocity(robot: m.RobotPosition) -> np.ndarray:
    return np.array([robot.vx_mm_s, robot.vy_mm_s, robot.vz_mm_s])
