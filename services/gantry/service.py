"""Gantry service: the crane keeps itself above the robot (paper §3).

Reads:      tracking-camera frames (stb/gantry/camera/frame, or a camera via OpenCV)
            the crane controller over Modbus/TCP (position, status)
Publishes:  stb/gantry/detections, stb/gantry/estimate, stb/gantry/setpoint, stb/gantry/state,
            stb/gantry/offload (gravity offload: the cable's tilt from the horizontal error)
Drives:     the crane controller: a setpoint every control period (4 Hz), ticking a fixed
            time after the controller reports its position (polled at 40 Hz, CycleSync), a
            heartbeat for its watchdog (10 Hz); holds when the estimate is stale or the
            marker is lost
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time

import numpy as np

from common import keys
from common import messages as m
from common.heightmap import HeightMap
from common.markers import closest, detect, to_message, warm_up
from common.node import Node, StartupError, run_every
from services.gantry.crane import CraneError, CraneReading, ModbusCrane
from services.gantry.cycle import CycleSync
from services.gantry.frames import FrameInbox, OpenCvFrames, decode
from services.gantry.locate import TrackingOptics, locate
from services.gantry.offload import offload
from services.gantry.predict import Estimate, make_predictor, prediction_horizon
from services.gantry.safety import SetpointGuard, Workspace
from services.gantry.settings import GantrySettings

log = logging.getLogger(__name__)


def run(node: Node, crane: ModbusCrane | None = None) -> None:
    s: GantrySettings = node.settings  # type: ignore[assignment]
    try:
        heights = HeightMap.load(s.height_map)
    except ValueError as err:
        raise StartupError(f"gantry.height_map: {err}") from err
    log.info("detector ready (%.1f s)", warm_up())  # before the crane is driven, not mid-run
    crane = crane or ModbusCrane(s.crane_host, s.crane_port, s.crane_timeout_s)
    if s.frames == "bus":
        inbox = FrameInbox()
        node.bus.subscribe(keys.GANTRY_FRAME, lambda msg: _put(inbox, msg))
    else:
        inbox = OpenCvFrames(s.frames.removeprefix("opencv:"), node.stop)
    control = Control(node, s, crane, heights, inbox)
    threading.Thread(target=run_every, args=(1 / s.heartbeat_hz, node.stop, control.heartbeat,
                                             "heartbeat"), name="heartbeat", daemon=True).start()
    try:
        run_every(1 / s.poll_hz, node.stop, control.poll, "crane poll")
    finally:
        crane.close()


def _put(inbox: FrameInbox, msg: m.CameraFrame) -> None:
    frame = decode(msg)
    if frame is not None:
        inbox.put(frame)


class Control:
    def __init__(self, node: Node, s: GantrySettings, crane: ModbusCrane, heights: HeightMap,
                 frames: FrameInbox) -> None:
        self.node, self.s, self.crane, self.heights, self.frames = node, s, crane, heights, frames
        self.optics = TrackingOptics(s.focal_mm, s.pixel_mm, s.ref_u, s.ref_v,
                                     s.lens_height_mm)
        self.predictor = make_predictor(s.algorithm, seed=s.seed,
                                        horizon_s=min(prediction_horizon(
                                            s.reaction_s, 1 / s.control_hz), s.max_horizon_s))
        self.guard = SetpointGuard(
            Workspace(s.x_min_mm, s.x_max_mm, s.y_min_mm, s.y_max_mm, s.workspace_margin_mm),
            s.max_speed_mm_s, s.max_accel_mm_s2, s.stale_after_s)
        self.estimate: Estimate | None = None
        self.estimate_s: float | None = None
        self.last_pixel: tuple[float, float] | None = None
        self.seq = 0
        self.reachable = True
        self.offload_warned = False
        self.last_tick = time.monotonic()
        self.sync = CycleSync(1 / s.control_hz, s.after_report_s)

    def heartbeat(self) -> None:
        """Only while the control loop is alive: a stuck or failing loop stops the heartbeat,
        and the crane's watchdog stops the crane."""
        if time.monotonic() - self.last_tick > 2.5 / self.s.control_hz:
            return
        with contextlib.suppress(CraneError):  # the control loop reports it
            self.crane.heartbeat()

    def poll(self) -> None:
        """Read the controller's report; tick when due (``CycleSync``)."""
        polled = time.monotonic()
        try:
            reading = self.crane.read()
        except CraneError as err:
            if self.sync.due(polled):
                self._unreachable(time.time(), err)
            return
        self.sync.observe(polled, (reading.x_mm, reading.y_mm))
        if self.sync.due(polled):
            self.tick(reading)

    def tick(self, reading: CraneReading) -> None:
        now = time.time()
        try:
            if not reading.enabled:
                log.info("crane not enabled (faults %#x): enabling", reading.faults)
                self.guard.reset()
                self.crane.enable()
        except CraneError as err:
            self._unreachable(now, err)
            return
        if not self.reachable:
            log.info("crane controller reachable again")
            self.reachable = True
        crane_xy = np.array([reading.x_mm, reading.y_mm])
        frame = self.frames.take()
        if frame is not None:
            self._measure(frame, crane_xy)
        decision = self.guard.decide(now, None if self.estimate is None else
                                     self.estimate.desired, self.estimate_s, crane_xy)
        try:
            self.crane.write_setpoint(*decision.setpoint)
        except CraneError as err:
            self._unreachable(now, err)
            return
        self.seq += 1
        self.last_tick = time.monotonic()
        self.node.bus.publish(keys.GANTRY_SETPOINT, m.CraneSetpoint(
            measured_s=now, seq=self.seq, x_mm=float(decision.setpoint[0]),
            y_mm=float(decision.setpoint[1]), hold=decision.hold))
        self.node.set_status("degraded" if decision.hold else "ok", decision.reason)
        self._state(now, "holding" if decision.hold else "tracking", reading)
        if self.estimate is not None and not decision.hold:
            self._offload(now, float(np.hypot(*(self.estimate.position - crane_xy))))

    def _offload(self, now: float, error_mm: float) -> None:
        o = offload(error_mm, self.s.cable_length_mm, self.s.offload_warn_pct)
        if o.warning and not self.offload_warned:
            log.warning("crane %.0f mm off the robot: the offload cable pulls %.1f %% sideways",
                        error_mm, o.horizontal_share_pct)
        self.offload_warned = o.warning
        self.node.bus.publish(keys.GANTRY_OFFLOAD, m.GravityOffload(
            measured_s=now, horizontal_error_mm=o.horizontal_error_mm,
            cable_length_mm=self.s.cable_length_mm, vertical_loss_pct=o.vertical_loss_pct,
            horizontal_share_pct=o.horizontal_share_pct, warning=o.warning))

    def _measure(self, frame: tuple[float, np.ndarray], crane_xy: np.ndarray) -> None:
        captured, image = frame
        result = detect(image, max_markers=20)
        height, width = image.shape
        self.node.bus.publish(keys.GANTRY_DETECTIONS,
                              to_message(result, "tracking", captured, width, height))
        marker = None
        if result.markers:
            ref = self.last_pixel or (self.optics.ref_u, self.optics.ref_v)
            marker = closest(result.markers, *ref)
        measured = None
        if marker is not None:
            self.last_pixel = (marker.u, marker.v)
            xyz = locate(marker.u, marker.v, crane_xy, self.optics, self.heights,
                         self.s.marker_height_mm)
            measured = xyz[:2]
        self.estimate = self.predictor.update(captured, measured)
        self.estimate_s = captured if self.estimate is not None else None
        e = self.estimate
        z = 0.0 if measured is None else float(xyz[2])
        self.node.bus.publish(keys.GANTRY_ESTIMATE, m.RobotEstimate(
            measured_s=captured, algorithm=self.s.algorithm, valid=e is not None,
            x_mm=float(e.position[0]) if e else 0.0, y_mm=float(e.position[1]) if e else 0.0,
            z_mm=z, vx_mm_s=float(e.velocity[0]) if e else 0.0,
            vy_mm_s=float(e.velocity[1]) if e else 0.0))

    def _unreachable(self, now: float, err: CraneError) -> None:
        self.guard.reset()  # the crane may have stopped meanwhile: start afresh when it is back
        if self.reachable:
            log.warning("%s", err)
        self.reachable = False
        self.node.set_status("degraded", str(err))
        self.node.bus.publish(keys.GANTRY_STATE, m.CraneState(
            measured_s=now, status="unreachable", x_mm=0.0, y_mm=0.0, target_x_mm=0.0,
            target_y_mm=0.0, enabled=False, moving=False, fault_bits=0))

    def _state(self, now: float, status: str, reading: CraneReading) -> None:
        self.node.bus.publish(keys.GANTRY_STATE, m.CraneState(
            measured_s=now, status=status if not reading.faults else "fault",
            x_mm=reading.x_mm, y_mm=reading.y_mm, target_x_mm=reading.target_x_mm,
            target_y_mm=reading.target_y_mm, enabled=reading.enabled, moving=reading.moving,
            fault_bits=reading.faults & 0xFFFF))
