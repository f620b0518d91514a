"""Sim service: the Space Testbed's devices, served on their real protocols.

Serves:     QTM RT on mocap.port (22223) and the crane's observation camera's pictures
            (VAPIX, 8083), each from a process of its own (services/sim/device_process.py);
            VAPIX HTTP per PTZ camera (8081, 8082), Modbus/TCP crane controller on
            crane.port (5020)
Publishes:  stb/gantry/camera/frame (CameraFrame, 25 Hz) as the tracking camera's host would,
            each tracking_camera.delay_s after its exposure ended;
            stb/sim/truth/robot/{robot}, stb/sim/truth/crane, stb/sim/truth/ptz/{camera}
            (ground truth, 20 Hz; for tests and evaluation only)
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import logging
import threading
from collections.abc import Callable
from functools import partial

import numpy as np

from common import keys
from common import messages as m
from common.errors import StartupError
from common.node import Node, run_every
from services.sim.camera_server import CameraServer, SimCamera
from services.sim.clock import Clock
from services.sim.crane_server import CraneServer
from services.sim.device_process import DeviceProcess
from services.sim.lab import Lab
from services.sim.mocap_server import MocapServer, MocapSource
from services.sim.scene import GroundView
from services.sim.settings import SimSettings

log = logging.getLogger(__name__)
CRANE_FEED_S = 0.01  # the crane's position to the QTM process: its marker within 10 ms


def run(node: Node[SimSettings]) -> None:
    settings = node.settings
    lab = Lab.build(settings)
    clock = Clock()
    qtm = DeviceProcess("qtm", settings, clock)
    processes = [qtm]
    try:
        if settings.observation_camera.enabled:
            processes.append(DeviceProcess("observation", settings, clock))
        cameras = start_cameras(lab, settings, clock)
    except StartupError:
        for process in processes:
            process.stop()
        raise
    devices = DeviceLoop(lab, settings, clock, serve_mocap=False)
    try:
        devices.start()
        log.info("sim running scenario %s (seed %d)", settings.scenario, settings.seed)
        if settings.calibrate_first and settings.scenario != "calibration":
            _start_robot_once_calibrated(
                node, lab, settings.calibrate_first, clock,
                also=partial(_start_robots, processes))
        threads = [
            _every(1 / (4 * settings.tracking_camera.rate_hz), node.stop,  # on time ± 10 ms
                   _frame_publisher(node, lab, settings, clock)),
            _every(1 / settings.truth_rate_hz, node.stop, _truth_publisher(node, lab, clock)),
            _every(CRANE_FEED_S, node.stop, _crane_feeder(lab, processes, clock)),
        ]
        node.stop.wait()
        for thread in threads:
            thread.join(timeout=2)
    finally:
        devices.stop()
        for process in processes:
            process.stop()
        for server in cameras:
            server.close()


def _start_robot_once_calibrated(node: Node, lab: Lab, cameras: list[str], clock: Clock,
                                 also: Callable[[float], None]) -> None:
    """The demo's order of things: the wand until every listed camera has a pose on the bus
    (from the calib service — the sim never hands out its own poses) or its collection failed
    (that camera stays uncalibrated: the demo carries on), then the robot."""
    calibrated: set[str] = set()
    lock = threading.Lock()

    def settled(camera: str, failed: str = "") -> None:
        with lock:
            if camera not in cameras or camera in calibrated:
                return
            if failed:
                log.warning("%s: calibration %s; the robot starts without it", camera, failed)
            calibrated.add(camera)
            if calibrated >= set(cameras):
                now = clock()
                lab.start_robot(now)
                also(now)  # the QTM process's lab

    def on_progress(progress: m.CollectProgress) -> None:
        if progress.state in ("failed", "cancelled"):
            settled(progress.camera, f"{progress.state}: {progress.message}")

    log.info("calibration phase: the wand moves until %s have poses", ", ".join(cameras))
    node.bus.subscribe(keys.CALIB_POSE, lambda pose: settled(pose.camera), latest=False)
    node.bus.subscribe(keys.CALIB_PROGRESS, on_progress, latest=False)
    for pose in node.bus.query_latest(keys.CALIB_POSE, timeout_s=1.0):
        settled(pose.camera)


def start_cameras(lab: Lab, settings: SimSettings, clock: Clock) -> list[CameraServer]:
    """The PTZ cameras' servers (the observation camera's runs in a process of its own)."""
    servers: list[CameraServer] = []
    for i, cam in enumerate(settings.cameras):
        sim_camera = SimCamera(cam.name, lab.heads[cam.name], lab.bright_points,
                               lab.ptz_glints, clock, np.random.default_rng((settings.seed, 3, i)),
                               cam.user, cam.password, cam.auth, mjpeg_fps=cam.mjpeg_fps,
                               ground=GroundView.of(lab.crater, settings.seed),
                               robots=lambda t: [lab.robot_pose(t)],
                               resolutions=cam.resolutions())
        try:
            servers.append(CameraServer(sim_camera, settings.host_of(cam.host), cam.port).start())
        except OSError as err:
            for server in servers:
                server.close()
            raise StartupError(f"camera {cam.name}: cannot listen on {cam.host}:{cam.port}: "
                               f"{err.strerror}") from err
        log.info("camera %s (VAPIX) on http://%s:%d", cam.name, cam.host, servers[-1].port)
    return servers


class DeviceLoop:
    """The asyncio devices (the Modbus crane, and the QTM RT server unless it has a process of
    its own: ``serve_mocap=False``) on a thread of their own."""

    def __init__(self, lab: Lab, settings: SimSettings, clock: Clock, *,
                 serve_mocap: bool = True) -> None:
        m_ = settings.mocap
        self.mocap = MocapServer(
            MocapSource(lab.labels, m_.rate_hz, lab.mocap_frame, clock, lab.body_points),
            settings.host_of(m_.host), m_.port) if serve_mocap else None
        self.crane = CraneServer(lab.crane, clock, lab.crane_lock,
                                 settings.host_of(settings.crane.host), settings.crane.port,
                                 registers=settings.crane.registers,
                                 estop_register=settings.crane.estop_register)
        self._loop = asyncio.new_event_loop()
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="devices", daemon=True)

    def start(self) -> None:
        self._thread.start()
        self._ready.wait(10)
        if self._error is not None:
            raise StartupError(str(self._error)) from self._error

    def _run(self) -> None:
        asyncio.set_event_loop(self._loop)
        try:
            self._loop.run_until_complete(self._start_servers())
        except OSError as err:
            self._error = err
            self._ready.set()
            return
        self._ready.set()
        self._loop.run_forever()

    async def _start_servers(self) -> None:
        if self.mocap is not None:
            try:
                await self.mocap.start()
            except OSError as err:
                raise OSError(f"QTM RT: cannot listen on {self.mocap.host}:{self.mocap.port}: "
                              f"{err.strerror}") from err
        self._crane_task = asyncio.create_task(self.crane.serve())
        await asyncio.sleep(0.05)
        if self._crane_task.done() and self._crane_task.exception() is not None:
            raise OSError(f"crane: cannot listen on {self.crane.host}:{self.crane.port}: "
                          f"{self._crane_task.exception()}")

    def stop(self) -> None:
        if not self._thread.is_alive():
            return

        async def shutdown() -> None:
            if self.mocap is not None:
                await self.mocap.close()
            with contextlib.suppress(Exception):
                await self.crane.close()
            others = [t for t in asyncio.all_tasks() if t is not asyncio.current_task()]
            for task in others:
                task.cancel()
            await asyncio.gather(*others, return_exceptions=True)
            self._loop.stop()

        asyncio.run_coroutine_threadsafe(shutdown(), self._loop)
        self._thread.join(timeout=5)


def _every(period_s: float, stop: threading.Event, action: Callable[[], None]
           ) -> threading.Thread:
    thread = threading.Thread(target=run_every, args=(period_s, stop, action, "publisher"),
                              daemon=True)
    thread.start()
    return thread


def _frame_publisher(node: Node, lab: Lab, settings: SimSettings, clock: Clock
                     ) -> Callable[[], None]:
    """Each frame goes out ``delay_s`` after its exposure ended, stamped with that time."""
    rng = np.random.default_rng((settings.seed, 5))
    cam = settings.tracking_camera
    seq = itertools.count()
    last = [-1]

    def publish() -> None:
        now = clock()
        number, captured = lab.newest_capture(now)
        if number <= last[0] or captured < 0:
            return
        last[0] = number
        lab.crane_state(now)  # the crane's history now covers the exposure
        image = lab.tracking_frame(captured, rng)
        node.bus.publish(keys.GANTRY_FRAME, m.CameraFrame(
            measured_s=clock.wall(captured), camera=cam.name, seq=next(seq),
            width_px=cam.width_px, height_px=cam.height_px, encoding="mono8",
            data=image.tobytes()))

    return publish


def _crane_feeder(lab: Lab, processes: list[DeviceProcess], clock: Clock
                  ) -> Callable[[], None]:
    """The crane's and the wand's positions to the devices in processes of their own: the
    QTM server's markers on the carriage and the wand, the observation camera looking
    down."""
    def feed() -> None:
        t = clock()
        position, velocity = lab.crane_state(t)
        wand = lab.wand_position(t)
        wand_velocity = lab.wand.velocity(t) if wand is not None else np.zeros(3)
        for process in processes:
            process.feed_crane(t, position, velocity)
            process.feed_wand(t, wand, wand_velocity)

    return feed


def _truth_publisher(node: Node, lab: Lab, clock: Clock) -> Callable[[], None]:
    def publish() -> None:
        t = clock()
        wall = clock.wall(t)
        robot, velocity = lab.robot(t), lab.robot_velocity(t)
        node.bus.publish(keys.TRUTH_ROBOT, m.RobotTruth(
            measured_s=wall, robot=lab.trajectory.name, x_mm=robot[0], y_mm=robot[1],
            z_mm=robot[2], vx_mm_s=velocity[0], vy_mm_s=velocity[1]), robot=lab.trajectory.name)
        crane, crane_v = lab.crane_state(t)
        node.bus.publish(keys.TRUTH_CRANE, m.CraneTruth(
            measured_s=wall, x_mm=crane[0], y_mm=crane[1], vx_mm_s=crane_v[0],
            vy_mm_s=crane_v[1]))
        for name, head in lab.heads.items():
            pan, tilt, zoom, _ = head.state(t)
            node.bus.publish(keys.TRUTH_PTZ, m.PtzTruth(
                measured_s=wall, camera=name, pan_deg=pan, tilt_deg=tilt, zoom=zoom),
                camera=name)

    return publish


def _start_robots(processes: list[DeviceProcess], now_s: float) -> None:
    for process in processes:
        process.start_robot(now_s)
