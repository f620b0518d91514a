"""PTZ service: points one AXIS camera at the tracked robot (paper §2.3).

Subscribes: stb/tracker/robot (RobotPosition); stb/calib/{camera}/pose only as news: the pose
            itself is asked of the calibration service's queryable (at start, when one is
            heard, every 30 s, every 5 s while the pictures disagree with it), never taken
            from a message anyone could put (services/ptz/pose_source.py)
            stb/ptz/{camera}/calibration (CalibrationMode: hold still and detect, with a lease)
            stb/ptz/{camera}/hand (PtzHand: an operator holds, moves or releases the camera)
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
from collections.abc import Callable

import zenoh

from common import codec, keys
from common import messages as m
from common.bus import Bus
from common.camera import Intrinsics, PtzLimits
from common.data_sheet import AXIS_215_PICTURE_PX
from common.markers import kernel_origin, warm_up
from common.node import Node, run_every
from common.ptz_settings import PtzSettings
from services.ptz.calibration import CalibrationHold
from services.ptz.camera import AxisPtzCamera, PtzCamera, PtzError, PtzRejected, http_client
from services.ptz.control import HAND_MOVES, PtzControl
from services.ptz.follow import Follower
from services.ptz.override import ManualOverride
from services.ptz.pointing import InfraredSchedule, PointingCheck
from services.ptz.pose_source import PoseAsking, choose
from services.ptz.preview import PreviewLoop
from services.ptz.vapix import VapixReplyError

log = logging.getLogger(__name__)
ASK_TICK_S = 0.1  # how often the pose asker looks whether asking is due
ASK_TIMEOUT_S = 1.0
PRESETS_EVERY_S = 30.0  # the camera's presets asked for again (someone may add one)


def make_camera(settings: PtzSettings) -> AxisPtzCamera:
    c = settings.connection()
    client = http_client(c.url, c.user, c.password.get_secret_value(), c.auth,
                         settings.timeout_s)
    return AxisPtzCamera(client, settings.instance)


def run(node: Node[PtzSettings], camera: PtzCamera | None = None) -> None:
    settings = node.settings
    log.info("detector ready (%.1f s, %s)", warm_up(), kernel_origin())  # previews, calibration
    # Position queries have a client of their own, like previews: a query in flight never
    # holds up a move command (that client is the injected camera's in tests).
    loop = PtzLoop(node, settings, camera or make_camera(settings),
                   queries=camera or make_camera(settings))
    name = settings.instance
    # a pose put on the key is only news: the pose itself is asked of calib (pose_source.py)
    node.bus.subscribe(keys.CALIB_POSE, lambda _msg: loop.asking.heard(), latest=True,
                       camera=name)
    threading.Thread(target=run_every, args=(ASK_TICK_S, node.stop, loop.ask_pose,
                                             "pose asker"), name="pose-asker",
                     daemon=True).start()
    node.bus.subscribe(keys.TRACKER_ROBOT, loop.on_robot)
    # latest wins: a burst of requests is not queued up to move the camera for seconds after
    node.bus.subscribe(keys.PTZ_CALIBRATION, loop.on_calibration, latest=True, camera=name)
    node.bus.subscribe(keys.PTZ_HAND, loop.on_hand, latest=False, camera=name)
    recordings = watch_recordings(node.bus, loop)
    preview = None
    if settings.preview_hz > 0:
        preview = loop.previews(make_camera(settings))  # its own client: never in the way
        preview.start()
    try:
        loop.run()
    finally:
        recordings.undeclare()
        if preview is not None:
            preview.join(timeout=2 * settings.timeout_s)


def watch_recordings(bus: Bus, loop: PtzLoop) -> zenoh.Subscriber:
    """Tells ``loop`` of each recording that begins or ends (``stb record``'s liveliness
    token), the ones running now included."""
    return bus.session.liveliness().declare_subscriber(
        keys.recording_pattern(bus.prefix), loop.on_recording, history=True)


class PtzLoop:
    """Commands go out as robot samples arrive (no polling delay); camera state is queried
    and published ``state_hz`` times a second. The rules are ``PtzControl``'s
    (services/ptz/control.py); one lock serialises the commands and guards it; it is not held
    while the state query waits for the camera. ``clock``: wall time; ``monotonic``: the
    calibration hold's waits (a test's simulated clock gives both, and drives ``step``,
    ``ask_pose`` and the previews' ``once`` itself)."""

    def __init__(self, node: Node, settings: PtzSettings, camera: PtzCamera,
                 queries: PtzCamera, clock: Callable[[], float] = time.time,
                 monotonic: Callable[[], float] = time.monotonic) -> None:
        self.node, self.settings, self.camera, self.queries = node, settings, camera, queries
        self.clock = clock
        self.control = PtzControl(
            Follower(deadband_deg=settings.deadband_deg, latency_s=settings.latency_s,
                     min_interval_s=1 / settings.command_hz, zoom=settings.zoom,
                     target_size_mm=settings.target_size_mm,
                     image_fraction=settings.image_fraction),
            ManualOverride(settings.manual_deg, settings.manual_pause_s),
            PointingCheck(settings.pointing_tolerance_deg, settings.pointing_persist,
                          daylight=settings.pointing_infrared_s == 0,
                          min_radius_px=settings.pointing_min_marker_px),
            name=camera.name, max_future_s=settings.bus.max_future_s,
            infrared=InfraredSchedule(settings.pointing_infrared_s, settings.pointing_confirm_s,
                                      settings.pointing_infrared_while_recording))
        self.lock = threading.Lock()
        name = settings.instance
        self.calibration = CalibrationHold(
            camera,
            lambda msg: node.bus.publish(keys.PTZ_DETECTIONS, msg, camera=name),
            lambda msg: node.bus.publish(keys.PTZ_SNAPSHOT, msg, camera=name),
            max_markers=settings.calibration_max_markers,
            moved=lambda pan, tilt: self.control.own_move(clock(), pan, tilt),
            monotonic=monotonic, wall=clock)
        self.state_due = 0.0
        self.presets: list[str] = []
        self.presets_due = 0.0
        self.asking = PoseAsking()
        self.recordings: set[str] = set()  # the keys of the recordings running
        self._period = 1 / settings.state_hz

    def previews(self, camera: PtzCamera) -> PreviewLoop:
        """The preview loop beside this one, on ``camera`` (a client of its own)."""
        settings = self.settings
        return PreviewLoop(
            camera, 1 / settings.preview_hz, self.on_preview,
            mount=lambda: self.control.pose, robot=lambda: self.control.robot,
            lens=lambda: self.control.lens,
            paused=lambda: self.calibration.active(self.clock()), stop=self.node.stop,
            infrared=self.infrared_now, marker_diameter_mm=settings.robot_marker_mm,
            clock=self.clock)

    def on_recording(self, sample: zenoh.Sample) -> None:
        """A recording began or ended (its liveliness token, ``keys.RECORDING``)."""
        self.recording(str(sample.key_expr), sample.kind == zenoh.SampleKind.PUT)

    def recording(self, key: str, running: bool) -> None:
        with self.lock:
            (self.recordings.add if running else self.recordings.discard)(key)

    def infrared_now(self, now: float) -> bool:
        """The preview loop's question: this preview in infrared?"""
        with self.lock:
            return self.control.infrared_due(now, recording=bool(self.recordings))

    def on_preview(self, preview: m.PtzPreview, intr: Intrinsics, infrared: bool) -> None:
        """Publish it, and judge from it how well the camera points (services/ptz/pointing)."""
        self.node.bus.publish(keys.PTZ_PREVIEW, preview, camera=self.settings.instance)
        with self.lock:
            if self.control.pointing.observe(preview, intr, infrared) and infrared:
                self.control.infrared.judged()

    def ask_pose(self) -> None:
        """Ask the calibration service for the camera's pose when it is due; take its answer
        (``pose_source.py``)."""
        now = self.clock()
        with self.lock:
            due = self.asking.due(now, doubting=self.control.pointing.problem() is not None)
        if not due:
            return
        self.asking.asked(now)
        name = self.settings.instance
        answers = self.node.bus.query_latest(keys.CALIB_POSE, timeout_s=ASK_TIMEOUT_S,
                                             every_answer=True, camera=name)
        pose, why = choose(answers, name)
        with self.lock:
            self.control.pose_problem = why if self.control.pose is None or answers else ""
            taken = "none" if pose is None else self.control.take_pose(pose, self.clock())
        if why and answers:
            log.warning("%s", why)
        if pose is None:
            return
        if taken == "future":
            key = keys.CALIB_POSE.key(self.node.bus.prefix, camera=name)
            self.node.bus.count_drop(key, codec.FROM_FUTURE, "pose measured "
                                     f"{pose.measured_s - now:.0f} s in the future: refused")
        elif taken == "taken":
            log.info("camera pose from calib (version %d, fit error %.2f px)", pose.version,
                     pose.mean_error_px)

    def on_calibration(self, msg: m.CalibrationMode) -> None:
        with self.lock:
            now = self.clock()
            try:
                self.calibration.on_request(msg, now, self.control.limits or PtzLimits())
            except PtzError as err:
                self._unreachable(now, err)
            if not self.calibration.active(now):
                self.control.calibration_left()

    def on_hand(self, msg: m.PtzHand) -> None:
        """An operator's hand (the page): hold, move, a preset, or follow again."""
        now = self.clock()
        with self.lock:
            refused = self.control.take_hand(msg, now, self.calibration.active(now))
            if refused is not None:
                log.warning("%s from %s refused: %s", msg.action, msg.operator, refused)
                return
            try:
                if msg.action == "move":
                    self.camera.move_to(msg.pan_deg, msg.tilt_deg, msg.zoom, self.settings.speed)
                elif msg.action == "nudge":
                    self.camera.nudge(msg.pan_deg or 0.0, msg.tilt_deg or 0.0, msg.zoom or 0)
                elif msg.action == "preset":
                    self.camera.goto_preset(msg.preset)
                if msg.action in HAND_MOVES:
                    self.control.moved_by_hand()
            except PtzError as err:
                log.warning("%s from %s: %s", msg.action, msg.operator, err)
                return
        self.state_due = 0.0  # the new state at once
        log.info("%s by %s%s", msg.action, msg.operator,
                 f" ({msg.preset})" if msg.action == "preset" else "")

    def on_robot(self, msg: m.RobotPosition) -> None:
        with self.lock:
            now = self.clock()
            command = self.control.command(msg, now, self.calibration.active(now))
            if command is None:
                return
            try:
                self.camera.move_to(command.pan_deg, command.tilt_deg, command.zoom,
                                    self.settings.speed, measured_s=command.measured_s)
                self.control.commanded(now, command)
            except PtzError as err:
                self._unreachable(now, err)

    def run(self) -> None:
        while not self.node.stop.wait(self._period):
            self._period = self.step(self.clock())

    def step(self, now: float) -> float:
        """A calibration snapshot when the mode is on, the camera's state when it is due;
        the wait until the next step."""
        state_period = 1 / self.settings.state_hz
        snapshot_period = 1 / self.settings.calibration_snapshot_hz
        with self.lock:
            if not self.control.may_try(now):
                return self._period
        try:
            with self.lock:
                calibrating = self._calibration_step(now)
            if now >= self.state_due:
                self.state_due = now + state_period
                self._report(now)
            with self.lock:
                self.control.answered()
        except PtzError as err:
            with self.lock:
                self._unreachable(now, err)
            calibrating = False
        return snapshot_period if calibrating else min(state_period,
                                                       max(self.state_due - now, 0.0))

    def _calibration_step(self, now: float) -> bool:
        """A calibration snapshot if the mode is on; leaves it when the lease ran out."""
        if self.calibration.request is None:
            return False
        if not self.calibration.active(now):
            self.calibration.leave()
            self.control.calibration_left()
            return False
        self.calibration.cycle()
        return True

    def _picture(self) -> tuple[int, int]:
        """The camera's full picture as it lists it; the AXIS 215's when it lists none."""
        try:
            return self.queries.picture()
        except (PtzRejected, VapixReplyError) as err:
            log.warning("camera %s does not list its picture sizes (%s): taken to be the AXIS "
                        "215's %d × %d", self.camera.name, err, *AXIS_215_PICTURE_PX)
            return AXIS_215_PICTURE_PX

    def _report(self, now: float) -> None:
        """Query the camera (without the lock) and publish its state."""
        if self.control.limits is None:
            limits, picture = self.queries.limits(), self._picture()
            with self.lock:
                self.control.camera_limits(limits, picture)
            log.info("camera %s limits: %s; picture %d × %d", self.camera.name, limits,
                     *picture)
        if now >= self.presets_due:
            self.presets, self.presets_due = self.queries.presets()[:64], now + PRESETS_EVERY_S
        position = self.queries.position()
        with self.lock:
            state = self.control.status(now, position.pan_deg, position.tilt_deg,
                                        self.calibration.active(now), position.zoom)
        self.node.set_status(state.health, state.health_why)
        self._publish(state.status, position.pan_deg, position.tilt_deg, position.zoom,
                      state.aim_error_deg, now, state.pointing_error_deg, state.problem)

    def _publish(self, status: m.PtzStatus, pan: float, tilt: float, zoom: int, error: float,
                 now: float, pointing_error: float | None = None, problem: str = "") -> None:
        held_by = m.who(self.control.held_by)
        pan, tilt, zoom = self.control.on_the_wire(pan, tilt, zoom)
        self.node.bus.publish(keys.PTZ_STATE, m.PtzState(
            measured_s=now, camera=self.settings.instance, status=status,
            pan_deg=pan, tilt_deg=tilt, zoom=zoom, focal_px=self.control.lens.focal_px(zoom),
            aim_error_deg=error, pointing_error_deg=pointing_error, pointing_problem=problem,
            held_by=held_by, presets=[m.name(p) for p in self.presets]),
            camera=self.settings.instance)

    def _unreachable(self, now: float, err: PtzError) -> None:
        self.node.set_status("degraded", str(err))
        self.control.failed(now)
        self._publish("camera_unreachable", 0.0, 0.0, 1, 0.0, now)
