"""Gantry service: the crane keeps itself above the robot (paper §3).

Reads:      tracking-camera frames (stb/gantry/camera/frame, or a camera via OpenCV),
            the motion capture's robot (stb/tracker/robot: to find a lost marker again, and
            to cross-check the tracking camera's fix) and the marker on the crane's carriage
            (stb/tracker/markers, label [gantry] crane_marker: to cross-check the crane's
            frame),
            operators' commands (stb/gantry/command/by/{sender}: arm, disarm, stop, reset),
            the crane controller over Modbus/TCP (position, status, faults, safety circuit)
Publishes:  stb/gantry/detections, stb/gantry/estimate, stb/gantry/setpoint, stb/gantry/state
            (with the mode: disarmed, armed, stopped; who changed it and why),
            stb/gantry/command/reply, stb/gantry/offload (the cable's tilt from the error)
Drives:     the crane controller, only while armed (services/gantry/modes.py): a setpoint
            every control period (4 Hz), ticking a fixed time after the controller reports its
            position (polled at 40 Hz, CycleSync), a heartbeat for its watchdog (10 Hz); holds
            when the estimate is stale or the marker is lost. It starts disarmed, never resets
            a latched fault itself, and stops (setpoint frozen, crane disabled) on an operator's
            stop, a fault, the safety circuit opening or the crane disabled at the controller.
"""

from __future__ import annotations

import contextlib
import logging
import random
import threading
import time
from typing import TypedDict

import numpy as np

from common import keys
from common import messages as m
from common.errors import StartupError
from common.heightmap import HeightMap
from common.markers import kernel_origin, to_message, warm_up
from common.node import Node, run_every, run_scheduled
from services.gantry.control import Controller, Fix, Step
from services.gantry.crane import ModbusCrane
from services.gantry.cycle import dithered_period_s
from services.gantry.frames import FrameInbox, FrameSource, OpenCvFrames
from services.gantry.loop import GantryLoop, Reply, Request
from services.gantry.modes import crane_status, health, heartbeat_due
from services.gantry.offload import offload
from services.gantry.reading import CraneError, CraneReading
from services.gantry.settings import GantrySettings

log = logging.getLogger(__name__)


def run(node: Node[GantrySettings]) -> None:
    s = node.settings
    heights = _height_map(node)
    if heights is None:
        return  # asked to stop while it waited
    log.info("detector ready (%.1f s, %s)", warm_up(), kernel_origin())  # before it drives
    crane = ModbusCrane(s.crane_host, s.crane_port, s.crane_timeout_s, s.crane,
                        s.crane.frame())
    frames: FrameSource
    if s.frames == "bus":
        inbox = frames = FrameInbox()
        # every frame, in order (at most the inbox's worth waiting): a stream's newest-only
        # delivery let a copy sent right after a real frame replace it whenever the handler
        # lagged, and the copy, alone at its capture time, was taken (the fault campaign's
        # drifting spoofed frames dragged the crane 190–202 mm on a busy machine); together,
        # the controller takes the one of the two the motion capture agrees with
        node.bus.subscribe(keys.GANTRY_FRAME, inbox.put_message, latest=False,
                           queue_size=inbox.keep)
    else:
        frames = OpenCvFrames(s.frames.removeprefix("opencv:"), node.stop)
    fix, crane_marker = LatestFix(), LatestMarker(s.crane_marker)
    node.bus.subscribe(keys.TRACKER_ROBOT, fix.put)
    if s.crane_marker and s.crane_check_mm > 0:
        node.bus.subscribe(keys.TRACKER_MARKERS, crane_marker.put)
    control = Control(node, s, GantryLoop(s, crane, frames, Controller(s, heights),
                                          time.time(), fix, crane_marker))
    node.bus.subscribe_keyed(keys.GANTRY_COMMAND, control.command)
    threading.Thread(target=run_every, args=(1 / s.heartbeat_hz, node.stop, control.heartbeat,
                                             "heartbeat"), name="heartbeat", daemon=True).start()
    log.info("disarmed: the crane moves once an operator arms the gantry (stb gantry arm)")
    try:
        rng = random.Random()
        run_scheduled(lambda due: control.loop.next_poll_s(
            due, dithered_period_s(1 / s.poll_hz, rng.random())), node.stop, control.poll,
            "crane poll")
    finally:
        crane.close()


def _height_map(node: Node[GantrySettings]) -> HeightMap | None:
    """The crater's height map. Not there yet (a fresh simulated lab: ``stb up`` imports the
    sim's scan as it starts), it is waited for, saying so in the health; a file that is there
    but not a height map stops the start (exit 4, naming the field)."""
    path = node.settings.height_map
    if not path.exists():
        log.warning("waiting for gantry.height_map %s (a simulated lab's first stb up makes "
                    "it from the sim's scan; a real lab's comes from stb crater import)", path)
        node.set_status("degraded", f"waiting for the crater height map {path}")
        while not path.exists():
            if node.stop.wait(0.2):
                return None
        node.set_status("ok")
    try:
        return HeightMap.load(path)
    except ValueError as err:
        raise StartupError(f"gantry.height_map: {err}") from err


class LatestFix:
    """The motion capture's latest fix of the robot (stb/tracker/robot)."""

    def __init__(self) -> None:
        self._fix: Fix | None = None

    def put(self, msg: m.RobotPosition) -> None:
        self._fix = Fix(msg.measured_s, np.array([msg.x_mm, msg.y_mm]),
                        np.array([msg.vx_mm_s, msg.vy_mm_s]))

    def __call__(self) -> Fix | None:
        return self._fix


class LatestMarker:
    """The motion capture's latest fix of one labelled marker (stb/tracker/markers): the one
    on the crane's carriage."""

    def __init__(self, label: str) -> None:
        self.label = label
        self._fix: Fix | None = None

    def put(self, msg: m.MarkerFrame) -> None:
        for marker in msg.markers:
            if marker.label == self.label:
                self._fix = Fix(msg.measured_s, np.array([marker.x_mm, marker.y_mm]))
                return

    def __call__(self) -> Fix | None:
        return self._fix


class CommandAudit(TypedDict, total=False):
    """The fields of ``CraneState`` that say what the last operator's command was."""

    command: str
    command_by: str
    command_s: float
    command_accepted: bool
    command_detail: str


class Control:
    """The loop on real time, and what it publishes."""

    def __init__(self, node: Node, s: GantrySettings, loop: GantryLoop) -> None:
        self.node, self.s, self.loop = node, s, loop
        self.seq = 0
        self.offload_warned = False
        self.last_tick = time.monotonic()

    def command(self, key: dict[str, str], msg: m.GantryCommand) -> None:
        """A command on its sender's key: limited and audited by that bus identity, or — for
        an identity that signs in its own users (the page) — by the user it names."""
        sender = key["sender"]
        if sender in self.s.command_delegates:
            by, rate_key = msg.operator, f"{sender}/{msg.operator}"
        else:
            by, rate_key = f"{sender} (as {msg.operator})", sender
        self.loop.request(Request(msg.command, m.who(by), msg.reason, msg.id, msg.measured_s,
                                  rate_key))

    def heartbeat(self) -> None:
        if not heartbeat_due(self.loop.armed, time.monotonic() - self.last_tick,
                             self.s.control_hz):
            return
        with contextlib.suppress(CraneError):  # the control loop reports it
            self.loop.crane.heartbeat()

    def poll(self) -> None:
        tick = self.loop.poll(time.time(), time.monotonic())
        if tick is None:
            return
        for reply in tick.replies:
            self._reply(tick.now_s, reply)
        if tick.reading is None:
            self._unreachable(tick.now_s, str(tick.error))
            return
        if tick.step is not None:
            self.last_tick = time.monotonic()
            self._publish(tick.now_s, tick.step, tick.reading)
        elif tick.replies or tick.changes:
            self._state(tick.now_s, tick.reading, hold=True)

    def _reply(self, now: float, reply: Reply) -> None:
        r, d = reply.request, reply.decision
        self.node.bus.publish(keys.GANTRY_COMMAND_REPLY, m.GantryCommandReply(
            measured_s=now, id=m.name(r.id), command=r.command, accepted=d.accepted,
            detail=m.text(d.detail), mode=d.mode))

    def _publish(self, now: float, step: Step, reading: CraneReading) -> None:
        if step.detection is not None and step.frame_s is not None:
            height, width = step.frame_shape
            self.node.bus.publish(keys.GANTRY_DETECTIONS, to_message(
                step.detection, "tracking", step.frame_s, width, height))
            self._estimate(step)
        armed = self.loop.armed
        if armed:
            self.seq += 1
            self.node.bus.publish(keys.GANTRY_SETPOINT, m.CraneSetpoint(
                measured_s=now, seq=self.seq, x_mm=float(step.setpoint[0]),
                y_mm=float(step.setpoint[1]), hold=step.hold))
        self._status(step)
        self._state(now, reading, hold=step.hold, reacquiring=step.reacquiring)
        if armed and step.estimate is not None and not step.hold:
            crane_xy = np.array([reading.x_mm, reading.y_mm])
            self._offload(now, float(np.hypot(*(step.estimate.position - crane_xy))))

    def _status(self, step: Step) -> None:
        modes = self.loop.modes
        untrusted = self.loop.geometry(time.time()) if modes.mode == "disarmed" else None
        self.node.set_status(*health(modes, untrusted=untrusted, disagreement=step.disagreement,
                                     hold=step.hold, hold_reason=step.reason))

    def _estimate(self, step: Step) -> None:
        e, xyz = step.estimate, step.measured_xyz
        assert step.frame_s is not None
        self.node.bus.publish(keys.GANTRY_ESTIMATE, m.RobotEstimate(
            measured_s=step.frame_s, algorithm=self.s.algorithm, valid=e is not None,
            x_mm=float(e.position[0]) if e else 0.0, y_mm=float(e.position[1]) if e else 0.0,
            z_mm=0.0 if xyz is None else float(xyz[2]),
            vx_mm_s=float(e.velocity[0]) if e else 0.0,
            vy_mm_s=float(e.velocity[1]) if e else 0.0))

    def _offload(self, now: float, error_mm: float) -> None:
        o = offload(error_mm, self.s.cable_length_mm, self.s.offload_warn_pct)
        if o.warning and not self.offload_warned:
            log.warning("crane %.0f mm off the robot: the offload cable pulls %.1f %% sideways",
                        error_mm, o.horizontal_share_pct)
        self.offload_warned = o.warning
        self.node.bus.publish(keys.GANTRY_OFFLOAD, m.GravityOffload(
            measured_s=now, horizontal_error_mm=o.horizontal_error_mm,
            cable_length_mm=self.s.cable_length_mm, vertical_loss_pct=o.vertical_loss_pct,
            horizontal_share_pct=o.horizontal_share_pct, warning=o.warning,
            warn_above_pct=self.s.offload_warn_pct))

    def _unreachable(self, now: float, error: str) -> None:
        self.node.set_status("degraded", error)
        modes = self.loop.modes
        self.node.bus.publish(keys.GANTRY_STATE, m.CraneState(
            measured_s=now, status="unreachable", x_mm=0.0, y_mm=0.0, target_x_mm=0.0,
            target_y_mm=0.0, enabled=False, moving=False, fault_bits=0,
            mode=modes.mode, mode_by=m.who(modes.by), mode_reason=m.text(modes.reason),
            mode_since_s=modes.since_s, **self._last_command()))

    def _last_command(self) -> CommandAudit:
        """The audit of the last operator's command: who, when, what and the answer."""
        if self.loop.last_reply is None:
            return {}
        at_s, reply = self.loop.last_reply
        return {"command": reply.request.command, "command_by": m.who(reply.request.by),
                "command_s": at_s, "command_accepted": reply.decision.accepted,
                "command_detail": m.text(reply.decision.detail)}

    def _state(self, now: float, reading: CraneReading, *, hold: bool,
               reacquiring: bool = False) -> None:
        modes = self.loop.modes
        self.node.bus.publish(keys.GANTRY_STATE, m.CraneState(
            measured_s=now, x_mm=reading.x_mm, y_mm=reading.y_mm,
            status=crane_status(modes.mode, reading, hold=hold, reacquiring=reacquiring),
            target_x_mm=reading.target_x_mm, target_y_mm=reading.target_y_mm,
            enabled=reading.enabled, moving=reading.moving, fault_bits=reading.faults & 0xFFFF,
            safety_ok=reading.safety_ok, mode=modes.mode, mode_by=m.who(modes.by),
            mode_reason=m.text(modes.reason), mode_since_s=modes.since_s, **self._last_command()))
