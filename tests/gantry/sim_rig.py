"""The gantry's loop on a simulated clock: the rules of the operator's modes, the stops and the
cross-checks, run in milliseconds.

``GantryLoop`` with the ``Controller`` the service builds, polling the sim's crane model through
the register map (``ModelCrane``, as the experiments do), fed the heartbeat as the service feeds
it (``heartbeat_due``), shown frames of the robot as the tracking camera sees it from where the
crane is (rendered by the sim's camera model, arriving after the bus's delay), the motion
capture's robot fix and the marker on the carriage. Only the wire is left out: the bus and
Modbus are tested in ``test_modes_service.py`` (one test per wire, on real time).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence

import numpy as np

from common.crane_registers import DEFAULT_MAP, RegisterMap
from common.heightmap import HeightMap
from common.names import GantryMode
from services.experiment.devices import ModelCrane, SimClock
from services.gantry.control import Controller, Fix
from services.gantry.frames import Frame
from services.gantry.loop import GantryLoop, Reply, Request
from services.gantry.modes import crane_status, heartbeat_due
from services.gantry.settings import CraneConnection, GantrySettings
from services.sim.crane import CraneModel, CraneParams
from services.sim.render import Blob, draw
from tests.gantry.camera import CAMERA, pixel_of
from tests.gantry.rig import GROUND_MM, MARKER_MM, RIG_PARAMS

POLL_S = 0.025  # the service's 40 Hz
HEARTBEAT_S = 0.1  # and its 10 Hz heartbeat
FRAME_S = 0.04  # frames at 25 Hz, as the real-time rig sends them
FRAME_DELAY_S = 0.03  # from exposure to the gantry, over the bus
Robot = Callable[[float], np.ndarray | None]

_ids = itertools.count()


def rig_settings(**changes: object) -> GantrySettings:
    """The real-time rig's settings (``conftest.rig``): a flat crater, the rig's marker height,
    a stale estimate after 0.6 s, commands as fast as a test sends them."""
    defaults: dict[str, object] = {"marker_height_mm": MARKER_MM, "stale_after_s": 0.6,
                                   "command_burst": 100, "command_per_s": 100.0}
    return GantrySettings(**{**defaults, **changes})


class CountingCrane(ModelCrane):
    """The crane's driver over the model, counting the setpoints the gantry writes."""

    setpoints = 0

    def write_setpoint(self, x_mm: float, y_mm: float) -> None:
        self.setpoints += 1
        super().write_setpoint(x_mm, y_mm)

    def foreign_setpoint(self, x_mm: float, y_mm: float) -> None:
        """Another Modbus client writes a setpoint into the registers (in the crane's
        counts, as the register map encodes them)."""
        r = self.registers
        self._write(r.setpoint_x, r.encode("setpoint_x", x_mm) + r.encode("setpoint_y", y_mm))


class RenderedFrames:
    """The ``FrameSource`` Protocol: the tracking camera's frames of the robot, exposed every
    ``FRAME_S`` from where the crane then was, arriving ``FRAME_DELAY_S`` later; none while
    ``paused``."""

    def __init__(self, clock: SimClock, model: CraneModel, robot: Robot,
                 paused: Callable[[float], bool]) -> None:
        self.clock, self.model, self.robot, self.paused = clock, model, robot, paused
        self.rng = np.random.default_rng(0)
        self._next = 0  # the next frame's number

    def take(self) -> Frame | None:
        recent = self.take_recent()
        return recent[0] if recent else None

    def take_recent(self) -> Sequence[Frame]:
        self.model.advance_to(self.clock())
        frames: list[Frame] = []
        while (t := self._next * FRAME_S) + FRAME_DELAY_S <= self.clock():
            self._next += 1
            if not self.paused(t):
                frames.append((t, self._render(t)))
        return frames[::-1][:8]

    def _render(self, t: float) -> np.ndarray:
        crane_xy, _ = self.model.state_at(t)
        robot = self.robot(t)
        blobs = []
        if robot is not None:
            u, v, r = pixel_of(np.array([*robot, GROUND_MM + MARKER_MM]), crane_xy)
            blobs.append(Blob(u, v, r, r))
        return draw(blobs, CAMERA.width_px, CAMERA.height_px, self.rng)


class SimGantry:
    """The gantry's loop and the sim's crane on one simulated clock (seconds from 0); the
    gantry polls every ``POLL_S`` from ``poll_phase_s`` (its clock's phase against the crane
    controller's cycle, which starts at 0)."""

    def __init__(self, settings: GantrySettings, robot: Robot, *,
                 registers: RegisterMap = DEFAULT_MAP, params: CraneParams = RIG_PARAMS,
                 mocap: bool = False, paused: Callable[[float], bool] = lambda _t: False,
                 crane_marker: Callable[[float], np.ndarray] = lambda _t: np.zeros(2),
                 poll_phase_s: float = 0.0) -> None:
        settings = settings.model_copy(update={
            "crane": CraneConnection(**{**settings.crane.model_dump(),
                                        **registers.model_dump()})})
        self.settings, self.robot, self.paused = settings, robot, paused
        self.clock = SimClock(0.0)
        self.model = CraneModel(params)
        self.crane = CountingCrane(self.model, self.clock, settings.crane,
                                   settings.crane.frame())
        self._mocap, self._crane_marker = mocap, crane_marker
        self.loop = self._started_loop()
        self.replies: list[Reply] = []
        self.setpoints: list[tuple[float, float, bool]] = []  # (x, y, hold) sent while armed
        self.status = "idle"
        self._fix: Fix | None = None
        self._last_step_s = -float("inf")
        self._next_poll_s, self._next_beat_s = poll_phase_s, 0.0  # polls: the gantry's clock

    def _started_loop(self) -> GantryLoop:
        heights = HeightMap(np.full((3, 3), GROUND_MM, np.float32), -5000, -5000, 5000)
        return GantryLoop(self.settings, self.crane,
                          RenderedFrames(self.clock, self.model, self.robot, self.paused),
                          Controller(self.settings, heights), self.now,
                          fix=self._robot_fix if self._mocap else lambda: None,
                          crane_marker=lambda: self._crane_fix(self._crane_marker),
                          clock=self.clock)

    def killed(self, seconds: float) -> None:
        """The gantry dead for ``seconds`` (no polls, no heartbeat, no setpoints), then
        started again: a new loop, disarmed, on the same crane."""
        self.clock.now_s += seconds
        self.model.advance_to(self.now)
        self.loop = self._started_loop()
        self._last_step_s = -float("inf")
        self._next_poll_s = self._next_beat_s = self.now

    @property
    def now(self) -> float:
        return self.clock.now_s

    @property
    def mode(self) -> GantryMode:
        return self.loop.modes.mode

    def state(self) -> tuple[np.ndarray, np.ndarray, bool, int]:
        """The crane's truth now: position, velocity, enabled, latched faults."""
        self.model.advance_to(self.now)
        return self.model.position, self.model.velocity, self.model.enabled, self.model.faults

    def run(self, seconds: float, until: Callable[[], object] | None = None) -> bool:
        """Polls and heartbeats for ``seconds`` of simulated time, or until ``until()`` holds
        (then True)."""
        end = self.now + seconds
        while self.now < end:
            if until is not None and until():
                return True
            self.clock.now_s = min(self._next_poll_s, self._next_beat_s)
            if self.now >= self._next_beat_s:
                self._heartbeat()
                self._next_beat_s += HEARTBEAT_S
            if self.now >= self._next_poll_s:
                self._poll()
                self._next_poll_s += POLL_S
        return until is not None and bool(until())

    def send(self, command: str, by: str = "operator (as test operator)") -> Reply:
        """An operator's command, answered at the next poll."""
        ident = f"sim-{next(_ids)}"
        self.loop.request(Request(command, by, "test", ident, self.now,  # type: ignore[arg-type]
                                  "operator"))
        assert self.run(1.0, lambda: self._reply(ident)), f"no reply to {command}"
        reply = self._reply(ident)
        assert reply is not None
        return reply

    def arm_when_in_view(self, within_s: float = 5.0) -> Reply:
        """Arm as an operator does once the gantry has an estimate: asked every 0.2 s."""
        deadline = self.now + within_s
        while self.now < deadline:
            if (reply := self.send("arm")).decision.accepted:
                return reply
            self.run(0.2)
        raise AssertionError(f"not armed within {within_s:g} s: {reply.decision.detail}")

    def _reply(self, ident: str) -> Reply | None:
        return next((r for r in self.replies if r.request.id == ident), None)

    def _heartbeat(self) -> None:
        if heartbeat_due(self.loop.armed, self.now - self._last_step_s, self.settings.control_hz):
            self.crane.heartbeat()

    def _poll(self) -> None:
        tick = self.loop.poll(self.now)
        if tick is None:
            return
        self.replies.extend(tick.replies)
        if tick.reading is None:
            return
        if tick.step is not None:
            self._last_step_s = self.now
            if self.loop.armed:
                x, y = tick.step.setpoint
                self.setpoints.append((float(x), float(y), tick.step.hold))
        self.status = crane_status(self.mode, tick.reading,
                                   hold=tick.step.hold if tick.step else True,
                                   reacquiring=bool(tick.step and tick.step.reacquiring))

    def _robot_fix(self) -> Fix | None:
        """The newest robot fix heard (the motion capture's 100 Hz; none while paused)."""
        t = np.floor(self.now / 0.01 + 1e-9) * 0.01
        if not self.paused(t) and (xy := self.robot(t)) is not None:
            self._fix = Fix(t, np.asarray(xy, float))
        return self._fix

    def _crane_fix(self, off: Callable[[float], np.ndarray]) -> Fix:
        """The marker on the carriage, ``off(t)`` from where the crane truly is."""
        t = np.floor(self.now / 0.01 + 1e-9) * 0.01
        self.model.advance_to(self.now)
        xy, _ = self.model.state_at(t)
        return Fix(t, xy + off(t))
