"""The PTZ service's loop on a simulated clock: its rules — following, the calibration mode and
its lease, an operator's hand, someone else's move, a camera that reboots, the pointing check
and its infrared previews — run in a fraction of their real time.

``PtzLoop`` and its previews as ``services/ptz/service.py`` builds them, on the real VAPIX
driver (``AxisPtzCamera``) whose requests the sim's camera answers in-process (``answer``, the
server's own: the head's motion and latency, its presets, its pictures) at the simulated time;
the bus in-process (what the loop publishes is kept, the pose is the fake calibration
service's). Only the wires are left out: HTTP and the bus are tested in ``test_service.py``.
"""

from __future__ import annotations

import heapq
import time
from collections.abc import Callable
from typing import Any, cast

import httpx
import numpy as np

from common import keys
from common import messages as m
from common.bus import Bus
from common.camera import Pose
from common.keys import Topic
from common.lab_views import CameraConnection
from common.node import Node
from common.ptz_settings import PtzSettings
from common.trace import TRACE_HEADER
from services.experiment.devices import SimClock
from services.ptz.camera import AxisPtzCamera
from services.ptz.service import ASK_TICK_S, PtzLoop
from services.sim.camera_server import SimCamera, answer
from services.sim.ptz import PtzHead

MOUNT = Pose(3550, 1090, 2190, 180, 30, 165)
TARGET = np.array([-300.0, 200.0, 100.0])
START_S = 1.8e9  # the simulated clock's wall time at the start (2027)
ROBOT_S = 0.05  # the tracker's robot samples, 20 a second
Robot = Callable[[float], np.ndarray | None]  # where the robot is (None: no sample)


class InProcessCamera(httpx.BaseTransport):
    """httpx to the sim's camera without a socket: each request answered by the sim's
    ``answer`` at the simulated time, as it arrives (the wall time: it waited for nothing);
    ``up`` False plays a camera that is off."""

    def __init__(self, camera: SimCamera) -> None:
        self.camera, self.up = camera, True

    def handle_request(self, request: httpx.Request) -> httpx.Response:
        if not self.up:
            raise httpx.ConnectError("the camera is off", request=request)
        reply = answer(self.camera, request.url.path, dict(request.url.params.multi_items()),
                       request.read(), request.headers.get(TRACE_HEADER), time.time())
        return httpx.Response(reply.status, headers={"content-type": reply.content_type},
                              content=reply.body)


class LocalBus:
    """What the loop asks of the bus, in-process: what it publishes is kept by topic, the
    pose query answered with the fake calibration service's pose, dropped messages counted."""

    prefix = "stb"

    def __init__(self) -> None:
        self.published: dict[str, list[m.Message]] = {}
        self.pose: m.CameraPose | None = None
        self.dropped: list[tuple[str, str]] = []

    def publish(self, topic: Topic[Any], msg: m.Message, **_params: object) -> bool:
        self.published.setdefault(topic.path, []).append(msg)
        return True

    def query_latest(self, _topic: Topic[Any], timeout_s: float = 2.0,
                     **_params: object) -> list[m.CameraPose]:
        return [] if self.pose is None else [self.pose]

    def count_drop(self, key: str, reason: str, _detail: str, **_kw: object) -> None:
        self.dropped.append((key, reason))

    def key_stats(self) -> dict:
        return {}


def true_pose(measured_s: float) -> m.CameraPose:
    """ptz1's pose as the calibration service would measure it, without error."""
    return m.CameraPose(measured_s=measured_s, camera="ptz1", **MOUNT.fields(), focal_px=743.1,
                        mean_error_px=1.0, passpoints=100)


def sim_camera(clock: Callable[[], float], target: Callable[[], np.ndarray],
               latency_s: float = 0.05) -> SimCamera:
    """ptz1 at ``MOUNT``, its head at home, seeing the robot marker at ``target()``."""
    return SimCamera("ptz1", PtzHead(MOUNT, latency_s=latency_s),
                     lambda _t: target()[None, :], [], clock, np.random.default_rng(0))


class SimPtz:
    """One PTZ service's loop (and previews when ``preview_hz`` > 0) with the sim's ptz1 on
    one simulated clock; robot samples from ``robot`` every ``ROBOT_S``."""

    def __init__(self, robot: Robot = lambda _t: TARGET, *, latency_s: float = 0.05,
                 **settings: Any) -> None:
        self.clock = SimClock(START_S)
        self.robot = robot
        self.target = TARGET
        self.camera = sim_camera(self.clock, lambda: self.target, latency_s)
        self.transport = InProcessCamera(self.camera)
        self.settings = PtzSettings(**{
            "instance": "ptz1", "state_hz": 10, "timeout_s": 0.3,
            "cameras": {"ptz1": CameraConnection(url="http://ptz1.sim")}, **settings})
        self.bus = LocalBus()
        self.node = Node("ptz", self.settings, cast(Bus, self.bus))
        driver = AxisPtzCamera(self.client(), "ptz1")
        self.loop = PtzLoop(self.node, self.settings, driver, queries=driver, clock=self.clock,
                            monotonic=self.clock)
        preview = self.loop.previews(driver) if self.settings.preview_hz > 0 else None
        self._events: list[tuple[float, int, Callable[[], float | None]]] = []
        self._order = 0
        self._at(0.0, self._step)
        self._at(0.0, self._ask)
        self._at(0.0, self._sample)
        if preview is not None:
            period = preview.period_s
            def previewed() -> float:
                preview.once()
                return period

            self._at(period, previewed)

    def client(self) -> httpx.Client:
        """An HTTP client of the sim's camera (in-process)."""
        return httpx.Client(transport=self.transport, base_url="http://ptz1.sim")

    # --- what the loop published ------------------------------------------------------------

    @property
    def states(self) -> list[m.PtzState]:
        return cast(list[m.PtzState], self.bus.published.get(keys.PTZ_STATE.path, []))

    def of(self, topic: Topic[Any]) -> list[Any]:
        return self.bus.published.get(topic.path, [])

    @property
    def now(self) -> float:
        """Seconds since the rig started."""
        return self.clock() - START_S

    # --- what comes in ------------------------------------------------------------------------

    def solve(self, news: bool = True, **changes: Any) -> m.CameraPose:
        """The calibration service stores a pose (the true one, with ``changes``) and puts
        the news on the key (or not: then the PTZ service finds it when it asks again)."""
        self.bus.pose = true_pose(self.clock()).model_copy(update=changes)
        if news:
            self.loop.asking.heard()
        return self.bus.pose

    def hand(self, action: m.HandAction, **values: Any) -> None:
        self.loop.on_hand(m.PtzHand(measured_s=self.clock(), camera="ptz1", action=action,
                                    operator="olga (web h)", **values))

    def calibration(self, active: bool = True, **values: Any) -> None:
        self.loop.on_calibration(m.CalibrationMode(
            measured_s=self.clock(), camera="ptz1", active=active, **values))

    # --- time -----------------------------------------------------------------------------

    def run(self, seconds: float) -> None:
        """``seconds`` of simulated time."""
        self.until(lambda: False, seconds, expect=False)

    def until(self, condition: Callable[[], bool], within_s: float,
              why: Callable[[], str] = lambda: "", *, expect: bool = True) -> float:
        """Runs until ``condition()`` holds (checked after each event); the simulated seconds
        it took. Fails after ``within_s`` when ``expect``."""
        start, end = self.clock(), self.clock() + within_s
        while self._events[0][0] <= end:
            at, _, action = heapq.heappop(self._events)
            self.clock.now_s = at
            again = action()
            if again is not None:
                self._at(at - START_S + again, action)
            if condition():
                return self.clock() - start
        self.clock.now_s = end
        assert not expect, f"not within {within_s} s of simulated time: {why()}"
        return within_s

    def _at(self, t: float, action: Callable[[], float | None]) -> None:
        self._order += 1
        heapq.heappush(self._events, (START_S + t, self._order, action))

    def _step(self) -> float:
        return max(self.loop.step(self.clock()), 0.001)

    def _ask(self) -> float:
        self.loop.ask_pose()
        return ASK_TICK_S

    def _sample(self) -> float:
        xyz = self.robot(self.now)
        if xyz is not None:
            self.target = xyz
            self.loop.on_robot(m.RobotPosition(
                measured_s=self.clock(), label="robot", x_mm=xyz[0], y_mm=xyz[1], z_mm=xyz[2],
                vx_mm_s=0.0, vy_mm_s=0.0, vz_mm_s=0.0))
        return ROBOT_S
