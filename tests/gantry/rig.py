"""The gantry service against the sim's Modbus crane controller on real time, with tracking
frames put on the bus by the test (rendered by the sim's camera model from a robot position
it chooses), and an operator who sends commands."""

from __future__ import annotations

import asyncio
import itertools
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import numpy as np
import pytest
from pymodbus.client import ModbusTcpClient

from common import keys
from common import messages as m
from common.bus import Bus
from common.crane_registers import DEFAULT_MAP, RegisterMap
from services.sim.crane import CraneModel, CraneParams
from services.sim.crane_server import ESTOP_REGISTER, CraneServer
from services.sim.render import Blob, draw
from tests.conftest import free_port, poll, wait_for
from tests.gantry.camera import CAMERA, pixel_of
from tests.ports import listening

GROUND_MM, MARKER_MM = 100.0, 80.0
_ids = itertools.count()
RIG_PARAMS = CraneParams(watchdog_s=0.5)


class CraneRig:
    """The sim's crane controller on a free port, on real time, in a thread of its own."""

    def __init__(self, registers: RegisterMap = DEFAULT_MAP,
                 params: CraneParams = RIG_PARAMS) -> None:
        self.port, self.registers = free_port(), registers
        t0 = time.monotonic()
        self.clock = lambda: time.monotonic() - t0
        self.model = CraneModel(params)
        self.lock = threading.Lock()
        self.server = CraneServer(self.model, self.clock, self.lock, "127.0.0.1", self.port,
                                  registers=registers)
        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()
        wait_for(lambda: listening(self.port), timeout=10,
                 why=lambda: f"no crane server on {self.port}")

    def _run(self) -> None:
        asyncio.set_event_loop(self.loop)
        self.loop.run_until_complete(self.server.serve())

    def state(self) -> tuple[np.ndarray, np.ndarray, bool, int]:
        with self.lock:
            self.model.advance_to(self.clock())
            return (self.model.position.copy(), self.model.velocity.copy(), self.model.enabled,
                    self.model.faults)

    def at_the_panel(self, control: int) -> None:
        """Someone at the controller writes its control word (0: disable)."""
        with self.lock:
            self.model.write_control(self.clock(), control)

    def press_estop(self, pressed: bool = True) -> None:
        """The sim's e-stop, as ``stb sim estop`` presses it: a Modbus write."""
        client = ModbusTcpClient("127.0.0.1", port=self.port, timeout=2)
        assert client.connect()
        try:
            reply = client.write_register(ESTOP_REGISTER, int(pressed),
                                          device_id=self.registers.unit_id)
            assert not reply.isError()
        finally:
            client.close()

    def close(self) -> None:
        asyncio.run_coroutine_threadsafe(self.server.close(), self.loop).result(5)
        self.loop.call_soon_threadsafe(self.loop.stop)


class Operator:
    """Sends gantry commands on the bus and waits for their replies."""

    def __init__(self, bus: Bus) -> None:
        self.bus = bus
        self.replies: list[m.GantryCommandReply] = []
        self.states: list[m.CraneState] = []
        bus.subscribe(keys.GANTRY_COMMAND_REPLY, self.replies.append, latest=False)
        bus.subscribe(keys.GANTRY_STATE, self.states.append, latest=False)

    def send(self, command: str, timeout: float = 3.0) -> m.GantryCommandReply:
        wait_for(lambda: self.states, timeout=10)  # the gantry is up (and listening)
        ident = self._publish(command)
        return wait_for(lambda: self._reply(ident), timeout=timeout)

    def arm_within(self, timeout: float, period: float = 0.5) -> m.GantryCommandReply:
        """Arm as an operator at a lab that is still starting would: wait for the gantry, ask
        again (every ``period``) while it does not answer or refuses (no estimate yet), at most
        ``timeout``; a reply that does not come is asked again, not a failure."""
        answer: m.GantryCommandReply | None = None

        def armed() -> m.GantryCommandReply | None:
            nonlocal answer
            if not self.states:
                return None
            ident = self._publish("arm")
            answer = poll(lambda: self._reply(ident), timeout=3) or answer
            return answer if answer is not None and answer.accepted else None

        accepted = poll(armed, timeout=timeout, period=period)
        if accepted:
            return accepted
        pytest.fail(f"the gantry was not armed within {timeout:g} s: "
                    + (f"last answer {answer.detail!r}" if answer else
                       "it answered nothing" if self.states else "it published no state"))

    def _publish(self, command: str) -> str:
        ident = f"test-{next(_ids)}"
        self.bus.publish(keys.GANTRY_COMMAND, m.GantryCommand(
            measured_s=time.time(), command=command, operator="test operator",  # type: ignore[arg-type]
            reason="test", id=ident), sender="operator")
        return ident

    def _reply(self, ident: str) -> m.GantryCommandReply | None:
        return next((r for r in self.replies if r.id == ident), None)

    def mode(self) -> str | None:
        return self.states[-1].mode if self.states else None


def frame(world: Bus, robot_xy: np.ndarray | None, crane_xy: np.ndarray, seq: int,
          rng: np.random.Generator, captured_s: float | None = None) -> None:
    """A frame of the robot seen from the crane at ``crane_xy``, stamped ``captured_s`` (the
    moment the crane was there; default now)."""
    blobs = []
    if robot_xy is not None:
        u, v, r = pixel_of(np.array([*robot_xy, GROUND_MM + MARKER_MM]), crane_xy)
        blobs.append(Blob(u, v, r, r))
    image = draw(blobs, CAMERA.width_px, CAMERA.height_px, rng)
    world.publish(keys.GANTRY_FRAME, m.CameraFrame(
        measured_s=captured_s or time.time(), camera="tracking", seq=seq,
        width_px=CAMERA.width_px,
        height_px=CAMERA.height_px, encoding="mono8", data=image.tobytes()))


def feed(crane: CraneRig, world: Bus, robot: Callable[[float], np.ndarray | None],
         seconds: float, stop: threading.Event | None = None, *, mocap: bool = False,
         paused: Callable[[float], bool] = lambda _t: False,
         crane_marker: Callable[[float], np.ndarray] = lambda _t: np.zeros(2)) -> None:
    """Frames at 25 Hz of the robot where ``robot(elapsed)`` says, seen from the crane (and
    its motion-capture fix on stb/tracker/robot if ``mocap``); nothing while ``paused``. The
    motion capture sees the marker on the crane's carriage all along (stb/tracker/markers:
    the rig's crane counts in the world's frame), ``crane_marker(elapsed)`` off the crane."""
    rng = np.random.default_rng(0)
    start = time.monotonic()
    seq = 0
    while (elapsed := time.monotonic() - start) < seconds and not (stop and stop.is_set()):
        captured = time.time()
        crane_xy, _, _, _ = crane.state()
        xy = robot(elapsed)
        marker = crane_xy + crane_marker(elapsed)
        world.publish(keys.TRACKER_MARKERS, m.MarkerFrame(
            measured_s=captured, frame=seq, markers=[m.Marker(
                label="crane", x_mm=float(marker[0]), y_mm=float(marker[1]), z_mm=3500.0)]))
        if not paused(elapsed):
            frame(world, xy, crane_xy, seq, rng, captured)
            if mocap and xy is not None:
                world.publish(keys.TRACKER_ROBOT, m.RobotPosition(
                    measured_s=time.time(), label="robot", x_mm=float(xy[0]),
                    y_mm=float(xy[1]), z_mm=GROUND_MM + MARKER_MM, vx_mm_s=0.0, vy_mm_s=0.0,
                    vz_mm_s=0.0))
        seq += 1
        time.sleep(0.04)  # paces the frames (25 Hz)


@contextmanager
def feeding(crane: CraneRig, world: Bus, robot: Callable[[float], np.ndarray | None],
            seconds: float = 60.0, **options: object) -> Iterator[None]:
    """Frames in the background while the block runs (``options``: those of ``feed``)."""
    stop = threading.Event()
    thread = threading.Thread(target=feed, args=(crane, world, robot, seconds, stop),
                              kwargs=options, daemon=True)
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join(5)


SETTLE_SAMPLE_S = 0.02  # the standing-robot tests sample the true crane every 20 ms …
SETTLE_SAMPLES = 300  # … for 6 s from its first pass within 20 mm


def off_from_the_first_pass(distance: Callable[[], float], step: Callable[[], object],
                            now: Callable[[], float], until_s: float) -> list[float]:
    """The crane's true distance to a robot standing still, once it first passed within
    20 mm: ``distance()`` sampled, then ``step()`` (``SETTLE_SAMPLE_S`` on its clock)."""
    off: list[float] = []
    while len(off) < SETTLE_SAMPLES and now() < until_s:
        d = distance()
        if off or d < 20.0:
            off.append(d)
        step()
    return off


def assert_never_swings_off(off: list[float]) -> None:
    """Within 15 mm at most a second after the first pass within 20 mm, never 15 mm off
    after."""
    assert len(off) == SETTLE_SAMPLES, f"never within 20 mm ({len(off)} samples after)"
    closed = next((i for i, d in enumerate(off) if d <= 15.0), None)
    assert closed is not None and closed * SETTLE_SAMPLE_S <= 1.0, \
        "within 15 mm at most 1 s after the 20 mm"
    after = off[closed:]
    assert max(after) <= 15.0, f"swung {max(after):.1f} mm off, " \
        f"{(closed + np.argmax(after)) * SETTLE_SAMPLE_S:.2f} s after"

