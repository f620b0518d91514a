"""The Qualisys driver and the tracker service against the sim's QTM RT server."""

from __future__ import annotations

import asyncio
import threading
import time
from collections.abc import Callable, Iterator

import numpy as np
import pytest

from common import keys
from common import messages as m
from common.bus import Bus
from common.node import Node
from common.qtm_params import bodies_from_xml, labels_from_xml
from services.sim.lab import Lab
from services.sim.mocap_server import MocapServer, MocapSource
from services.tracker.mocap import QualisysMocap
from services.tracker.service import run
from services.tracker.settings import TrackerSettings
from tests.conftest import free_port, until_heard, wait_for

FRESH_S = 0.005  # between a fake driver's fresh frames (QTM at 200 Hz): captured in the last 0.2 s


class QtmThread:
    """The sim's QTM RT server on a loop thread of its own; stop() and start() it again."""

    def __init__(self, lab: Lab, port: int, start_s: float = 0.0) -> None:
        """``start_s``: the capture's time now (the locomotive waits 2 s before it moves)."""
        self.lab, self.port, self.t0 = lab, port, time.monotonic() - start_s
        self.loop = asyncio.new_event_loop()
        threading.Thread(target=self.loop.run_forever, daemon=True).start()
        self.server: MocapServer | None = None

    def sim_time(self) -> float:
        return time.monotonic() - self.t0

    def start(self) -> None:
        rate = self.lab.settings.mocap.rate_hz
        source = MocapSource(self.lab.labels, rate, self.lab.mocap_frame, self.sim_time,
                             self.lab.body_points)
        self.server = MocapServer(source, "127.0.0.1", self.port)
        asyncio.run_coroutine_threadsafe(self.server.start(), self.loop).result(5)

    def stop(self) -> None:
        if self.server is not None:
            asyncio.run_coroutine_threadsafe(self.server.close(), self.loop).result(5)
            self.server = None


@pytest.fixture
def qtm(lab: Lab) -> Iterator[QtmThread]:
    server = QtmThread(lab, free_port())
    server.start()
    yield server
    server.stop()
    server.loop.call_soon_threadsafe(server.loop.stop)


def _stream(port: int, count: int) -> tuple[list[m.MarkerFrame], list[tuple[bool, str]]]:
    """The driver's first ``count`` frames (and more that came meanwhile) and its states."""
    frames: list[m.MarkerFrame] = []
    states: list[tuple[bool, str]] = []
    stop = threading.Event()
    driver = QualisysMocap("127.0.0.1", port, retry_initial_s=0.1, retry_max_s=0.2)
    thread = threading.Thread(target=driver.run, args=(frames.append, stop,
                                                       lambda *s: states.append(s)))
    thread.start()
    try:
        wait_for(lambda: len(frames) >= count, timeout=30, why=lambda: f"{len(frames)} frames")
    finally:
        stop.set()
    thread.join(5)
    assert not thread.is_alive(), "the driver stops when asked"
    return frames, states


def test_driver_streams_labelled_frames_equal_to_the_truth(lab: Lab, qtm: QtmThread) -> None:
    frames, states = _stream(qtm.port, 100)
    assert states[0][0] is True and "streaming" in states[0][1]
    labels = {mk.label for f in frames for mk in f.markers}
    assert {"robot", "static_1", "static_2", "static_3"} <= labels
    errors = []
    for frame in frames:
        robot = [mk for mk in frame.markers if mk.label == "robot"]
        if robot:
            truth = lab.robot(frame.frame / lab.settings.mocap.rate_hz)
            errors.append(np.linalg.norm([robot[0].x_mm - truth[0], robot[0].y_mm - truth[1],
                                          robot[0].z_mm - truth[2]]))
    assert np.sqrt(np.mean(np.square(errors))) < 1.5
    stamps = np.array([f.measured_s for f in frames])
    assert np.all(np.diff(stamps) > 0) and abs(time.time() - stamps[-1]) < 1.5


def test_driver_reconnects_when_qtm_comes_back(qtm: QtmThread) -> None:
    frames: list[m.MarkerFrame] = []
    states: list[tuple[bool, str]] = []
    stop = threading.Event()
    driver = QualisysMocap("127.0.0.1", qtm.port, retry_initial_s=0.1, retry_max_s=0.3)
    thread = threading.Thread(target=driver.run, args=(frames.append, stop,
                                                       lambda *s: states.append(s)))
    thread.start()
    try:
        wait_for(lambda: len(frames) > 10)
        qtm.stop()
        wait_for(lambda: states and states[-1][0] is False, timeout=5)
        count = len(frames)
        away = len(states)
        # QTM stays away while the driver tries again (each try that fails says so)
        wait_for(lambda: sum(not up for up, _ in states[away:]) >= 2, timeout=5)
        qtm.start()
        wait_for(lambda: len(frames) > count + 20, timeout=5)
        assert states[-1][0] is True
    finally:
        stop.set()
        thread.join(5)


def test_missing_markers_are_left_out_never_zero(lab: Lab, qtm: QtmThread) -> None:
    frames, _ = _stream(qtm.port, 250)
    counts = [len(f.markers) for f in frames]
    assert min(counts) < max(counts), "some frames lose a marker"
    assert all(mk.x_mm or mk.y_mm or mk.z_mm for f in frames for mk in f.markers)


def test_labels_from_the_parameters_xml() -> None:
    xml = (b"<QTM_Parameters_Ver_1.25><The_3D><Labels>2</Labels><Label><Name>robot</Name>"
           b"</Label><Label><Name>static_1</Name></Label></The_3D></QTM_Parameters_Ver_1.25>")
    assert labels_from_xml(xml) == ["robot", "static_1"]


def test_service_publishes_markers_and_the_robot(lab: Lab, qtm: QtmThread,
                                                 make_bus: Callable[..., Bus]) -> None:
    service_bus, watcher = make_bus(), make_bus()
    node = Node("tracker", TrackerSettings(qtm_port=qtm.port), service_bus)
    robots: list[m.RobotPosition] = []
    frames: list[m.MarkerFrame] = []
    watcher.subscribe(keys.TRACKER_ROBOT, robots.append, latest=False)
    watcher.subscribe(keys.TRACKER_MARKERS, frames.append)
    thread = threading.Thread(target=run, args=(node,))
    thread.start()
    try:
        wait_for(lambda: len(robots) > 50 and frames, timeout=10)
        last = robots[-1]
        truth = lab.robot(qtm.sim_time())
        assert np.hypot(last.x_mm - truth[0], last.y_mm - truth[1]) < 60  # ≤ 0.2 s at 290 mm/s
        assert last.label == "robot"
        assert node.health().status == "ok"
    finally:
        node.stop.set()
        thread.join(5)


class BacklogMocap:
    """Fresh frames (200 Hz, the newest captured now), then a backlog as after a 2 s stall
    (captured 2.0 … 0.6 s ago, arriving at once), then fresh frames again."""

    def __init__(self) -> None:
        self.stale = 0

    def run(self, on_frame: Callable[[m.MarkerFrame], None], stop: threading.Event,
            on_state: Callable[[bool, str], None]) -> None:
        on_state(True, "backlog")

        def frame(k: int, captured_s: float) -> m.MarkerFrame:
            return m.MarkerFrame(measured_s=captured_s, frame=k, markers=[
                m.Marker(label="robot", x_mm=float(k), y_mm=0.0, z_mm=100.0)])

        now = time.time()
        for k in range(20):
            on_frame(frame(k, now - (19 - k) * FRESH_S))
        now = time.time()
        for k in range(20, 160):
            self.stale += 1
            on_frame(frame(k, now - 2.0 + (k - 20) * 0.01))
        now = time.time()
        for k in range(160, 180):
            on_frame(frame(k, now - (179 - k) * FRESH_S))
        stop.wait(5)


def test_a_stale_backlog_is_dropped_and_counted_not_sent_as_fresh(
        make_bus: Callable[..., Bus]) -> None:
    service_bus, watcher = make_bus(), make_bus()
    node = Node("tracker", TrackerSettings(), service_bus)
    robots: list[m.RobotPosition] = []
    watcher.subscribe(keys.TRACKER_ROBOT, robots.append, latest=False)
    mocap = BacklogMocap()
    thread = threading.Thread(target=run, args=(node, mocap))
    thread.start()
    try:
        wait_for(lambda: any(r.x_mm >= 179 for r in robots), timeout=10)
        ages = [r.sent_s - r.measured_s for r in robots]
        assert max(ages) < node.settings.bus.max_age_s, max(ages)
        assert not any(20 <= r.x_mm < 160 for r in robots), "nothing of the backlog went out"
        dropped = node.health().keys[keys.TRACKER_ROBOT.key(service_bus.prefix)].dropped
        assert dropped.get("stale") == mocap.stale
    finally:
        node.stop.set()
        thread.join(10)


@pytest.fixture
def moving_qtm(lab: Lab) -> Iterator[QtmThread]:
    server = QtmThread(lab, free_port(), start_s=4.0)
    server.start()
    yield server
    server.stop()
    server.loop.call_soon_threadsafe(server.loop.stop)


def _tracker(settings: TrackerSettings, make_bus: Callable[..., Bus]
             ) -> tuple[Node, list[m.RobotPosition], list[m.MarkerFrame], threading.Thread]:
    service_bus, watcher = make_bus(), make_bus()
    node = Node("tracker", settings, service_bus)
    robots: list[m.RobotPosition] = []
    frames: list[m.MarkerFrame] = []
    watcher.subscribe(keys.TRACKER_ROBOT, robots.append, latest=False)
    watcher.subscribe(keys.TRACKER_MARKERS, frames.append, latest=False)
    thread = threading.Thread(target=run, args=(node,))
    thread.start()
    return node, robots, frames, thread


def test_service_publishes_the_robot_body_with_its_orientation(
        lab: Lab, moving_qtm: QtmThread, make_bus: Callable[..., Bus]) -> None:
    node, robots, frames, thread = _tracker(
        TrackerSettings(qtm_port=moving_qtm.port, robot_body="robot"), make_bus)
    try:
        wait_for(lambda: len(robots) > 50, timeout=10)
        last = robots[-1]
        assert (last.body, last.label) == ("robot", "")
        q = np.array([last.qw, last.qx, last.qy, last.qz])
        assert abs(np.linalg.norm(q) - 1) < 1e-6
        assert last.qz is not None and last.qw is not None
        yaw = np.degrees(2 * np.arctan2(last.qz, last.qw))  # a level body turns about z only
        heading = np.degrees(np.arctan2(last.vy_mm_s, last.vx_mm_s))
        assert abs((yaw - heading + 180) % 360 - 180) < 5, (yaw, heading)
        truth = lab.robot(moving_qtm.sim_time())
        assert np.hypot(last.x_mm - truth[0], last.y_mm - truth[1]) < 60
        assert {b.name for f in frames for b in f.bodies} == {"robot"}, \
            "the wand's body is lost while the robot runs: absent, never zero"
        assert node.health().status == "ok"
    finally:
        node.stop.set()
        thread.join(5)


def test_an_unknown_body_is_named_in_the_health_with_those_qtm_has(
        qtm: QtmThread, make_bus: Callable[..., Bus]) -> None:
    node, robots, frames, thread = _tracker(
        TrackerSettings(qtm_port=qtm.port, robot_body="rover"), make_bus)
    try:
        wait_for(lambda: node.health().status == "degraded" and len(frames) > 20, timeout=10)
        assert "'rover'" in node.health().detail and "robot, wand" in node.health().detail
        assert not robots, "no robot without its body"
    finally:
        node.stop.set()
        thread.join(5)


class LosingBody:
    """The robot's body for 20 frames, then QTM loses it (6D NaN: absent from the frame)."""

    def run(self, on_frame: Callable[[m.MarkerFrame], None], stop: threading.Event,
            on_state: Callable[[bool, str], None]) -> None:
        on_state(True, "bodies")
        now = time.time()
        for k in range(41):  # frame 40 has the body again: it says the 20 before were seen
            bodies = [m.RigidBody(name="robot", x_mm=float(k), y_mm=5.0, z_mm=80.0, qw=1.0,
                                  qx=0.0, qy=0.0, qz=0.0)] if k < 20 or k == 40 else []
            on_frame(m.MarkerFrame(measured_s=now - (40 - k) * FRESH_S, frame=k, markers=[
                m.Marker(label="robot", x_mm=1.0, y_mm=2.0, z_mm=3.0)], bodies=bodies))
        stop.wait(5)


def test_a_body_lost_by_qtm_gives_no_robot_sample_never_a_zero_or_its_marker(
        make_bus: Callable[..., Bus]) -> None:
    service_bus, watcher = make_bus(), make_bus()
    node = Node("tracker", TrackerSettings(robot_body="robot"), service_bus)
    robots: list[m.RobotPosition] = []
    watcher.subscribe(keys.TRACKER_ROBOT, robots.append, latest=False)
    # the body's 20 frames go out in 0.2 s: only once the watcher's subscription has reached
    # the tracker's session (a CI run lost the first few to its propagation)
    until_heard(service_bus, "stb/tracker/robot")
    thread = threading.Thread(target=run, args=(node, LosingBody()))
    thread.start()
    try:
        # the frames are handled in order: the sample of frame 40 comes after 20–39 were seen
        wait_for(lambda: any(r.x_mm == 40.0 for r in robots), timeout=10)
        assert [r.x_mm for r in robots] == [*map(float, range(20)), 40.0], \
            "the 20 frames without the body give no sample"
        assert all(r.body == "robot" and r.qw == 1.0 for r in robots)
    finally:
        node.stop.set()
        thread.join(10)


def test_bodies_from_the_parameters_xml() -> None:
    xml = ("<QTM_Parameters_Ver_1.25><The_6D><Bodies>2</Bodies><Body><Name>robot</Name>"
           "</Body><Body><Name> wand </Name></Body></The_6D></QTM_Parameters_Ver_1.25>")
    assert bodies_from_xml(xml) == ["robot", "wand"]
