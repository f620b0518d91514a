"""Devices of the sim that are machines of their own in a lab, each in a process of its own:
the QTM RT server (``"qtm"``) and the crane's observation camera (``"observation"``).

A real QTM is a machine of its own: the sim's camera rendering, HTTP servers and tracking
camera must not hold its frames back (at 1000 Hz, sharing the sim's one interpreter delayed
frames by up to 10 ms). A real observation camera renders and encodes on its own processor,
so the sim's does so in a process of its own that takes only the processor time the lab's
processes leave (``SCHED_IDLE``). (Under compose on two cores, ptz1's calibration measured
1.7–2.1 px with the observation camera drawn in the sim's interpreter, 1.2–1.5 px with it
here, 0.1–0.3 px with nobody asking for its pictures: docs/deployment.md.) Each process builds the
same Lab from the same settings on the same sim time (a shared monotonic origin); the one
thing decided at run time, when the robot starts, comes over a shared value, and so does the
crane, whose model the Modbus clients drive in the sim's own process: its position and
velocity at a time (``feed_crane``, 100 a second), from which the motion capture places the
crane's marker and the observation camera looks down. A process ends with the sim: when told
to, or when its parent is gone.
"""

from __future__ import annotations

import asyncio
import logging
import math
import multiprocessing as mp
import os
import time
from collections.abc import Callable
from multiprocessing.connection import Connection
from multiprocessing.sharedctypes import Synchronized, SynchronizedArray

import numpy as np

from common.errors import StartupError
from services.sim.clock import Clock
from services.sim.lab import Lab
from services.sim.mocap_server import MocapServer, MocapSource
from services.sim.settings import SimSettings

log = logging.getLogger(__name__)
START_TIMEOUT_S = 60.0


class DeviceProcess:
    """Starts the device's server (raising StartupError with the reason when it cannot
    listen); ``kind``: "qtm" or "observation"."""

    def __init__(self, kind: str, settings: SimSettings, clock: Clock) -> None:
        context = mp.get_context("spawn")  # no copy of the sim's threads and sockets
        self._robot_start = context.Value("d", math.nan, lock=False)
        self._crane = context.Array("d", [math.nan] * 5)  # t, x, y, vx, vy (world)
        self._wand = context.Array("d", [math.nan] * 7)  # t, x, y, z, vx, vy, vz (world)
        self._stop = context.Event()
        ours, theirs = context.Pipe()
        self._process = context.Process(
            target=_serve, name=f"sim-{kind}", daemon=True,
            args=(kind, settings.model_dump_json(), clock.t0_monotonic, self._robot_start,
                  self._crane, self._wand, self._stop, theirs, os.getpid()))
        self._process.start()
        if not ours.poll(START_TIMEOUT_S):
            self.stop()
            raise StartupError(f"the sim's {kind} did not start within {START_TIMEOUT_S:g} s")
        self.port, error = ours.recv()
        if error:
            self.stop()
            raise StartupError(error)

    def start_robot(self, t: float) -> None:
        self._robot_start.value = t

    def feed_crane(self, t: float, position: np.ndarray, velocity: np.ndarray) -> None:
        """Where the crane is (world, mm) and how fast it goes at sim time ``t``."""
        with self._crane.get_lock():
            self._crane[:] = [t, *map(float, position[:2]), *map(float, velocity[:2])]

    def feed_wand(self, t: float, position: np.ndarray | None, velocity: np.ndarray) -> None:
        """Where the calibration wand is (world, mm; None: gone) and how fast it goes at sim
        time ``t``: its carrier watches the cameras, which are in the sim's process."""
        at = [math.nan] * 3 if position is None else [float(v) for v in position]
        with self._wand.get_lock():
            self._wand[:] = [t, *at, *map(float, velocity)]

    def stop(self) -> None:
        self._stop.set()
        self._process.join(5)
        if self._process.is_alive():
            self._process.kill()
            self._process.join(5)


def _serve(kind: str, settings_json: str, t0_monotonic: float, robot_start: Synchronized,
           crane: SynchronizedArray, wand: SynchronizedArray, stop: mp.synchronize.Event,
           conn: Connection,
           parent_pid: int) -> None:
    settings = SimSettings.model_validate_json(settings_json)
    lab = Lab.build(settings)
    clock = Clock(t0_monotonic)
    placed = lab.crane_world_at(0.0)

    def crane_at(t: float) -> np.ndarray:
        with crane.get_lock():
            t0, x, y, vx, vy = crane[:]
        if math.isnan(t0):
            return placed  # not fed yet: where the crane was put at the start
        return np.array([x, y]) + np.array([vx, vy]) * (t - t0)

    def started(t: float) -> None:
        """The robot's scenario has started by ``t``, once the sim says it did."""
        if lab.robot_start_s is None and not math.isnan(robot_start.value):
            lab.start_robot(robot_start.value)

    def wand_at(t: float) -> np.ndarray | None:
        with wand.get_lock():
            t0, *fed = wand[:]
        if math.isnan(t0) or math.isnan(fed[0]):
            return None  # not fed yet, or gone
        return np.array(fed[:3]) + np.array(fed[3:]) * (t - t0)

    lab.crane_feed = crane_at
    lab.wand_feed = wand_at

    def running() -> bool:
        return not stop.is_set() and os.getppid() == parent_pid

    if kind == "observation":
        _serve_observation(lab, settings, clock, started, conn, running)
    else:
        _serve_qtm(lab, settings, clock, started, conn, running)


def _serve_qtm(lab: Lab, settings: SimSettings, clock: Clock, started: Callable[[float], None],
               conn: Connection, running: Callable[[], bool]) -> None:
    def frame_at(number: int):  # noqa: ANN202 - a MocapFrame
        started(number)
        return lab.mocap_frame(number)

    m = settings.mocap
    server = MocapServer(MocapSource(lab.labels, m.rate_hz, frame_at, clock, lab.body_points),
                         settings.host_of(m.host), m.port)

    async def main() -> None:
        try:
            await server.start()
        except OSError as err:
            conn.send((m.port, f"QTM RT: cannot listen on {m.host}:{m.port}: {err.strerror}"))
            return
        conn.send((server.port, ""))
        while running():
            await asyncio.sleep(0.2)
        await server.close()

    asyncio.run(main())


def _serve_observation(lab: Lab, settings: SimSettings, clock: Clock,
                       started: Callable[[float], None], conn: Connection,
                       running: Callable[[], bool]) -> None:
    # Here, not at the top: the QTM process draws no picture and does without OpenCV.
    from services.sim.camera_server import CameraServer
    from services.sim.observation import observation_camera

    o = settings.observation_camera
    assert lab.crane_feed is not None
    # A real camera renders on a processor of its own: here it takes only what the lab's
    # processes leave (no privilege is needed to lower oneself).
    os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
    camera = observation_camera(lab, settings, clock, lab.crane_feed, started)
    try:
        server = CameraServer(camera, settings.host_of(o.host), o.port).start()
    except OSError as err:
        conn.send((o.port, f"camera {o.name}: cannot listen on {o.host}:{o.port}: "
                           f"{err.strerror}"))
        return
    conn.send((server.port, ""))
    while running():
        time.sleep(0.2)
    server.close()
