"""The PTZ service with the sim's camera over HTTP and a loopback bus (the test plays calib
and tracker by publishing a pose and robot positions): one test per wire — following, the
previews, the pose asked of calib and never taken from its key, a camera away. Its rules on a
simulated clock: ``test_loop_rules.py``."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator

import cv2
import numpy as np
import pytest

from common import keys
from common import messages as m
from common.bus import Bus
from common.lab_views import CameraConnection
from common.node import Node
from common.ptz_lens import axis_215_px
from common.ptz_settings import PtzSettings
from services.ptz.aim import aim_error_deg
from services.ptz.service import run
from services.sim.camera_server import CameraServer
from tests.conftest import free_port, wait_for
from tests.ptz.sim_rig import MOUNT, TARGET, sim_camera, true_pose


def _camera_server(port: int) -> CameraServer:
    t0 = time.monotonic()
    return CameraServer(sim_camera(lambda: time.monotonic() - t0, lambda: TARGET),
                        "127.0.0.1", port).start()


@pytest.fixture
def service(make_bus: Callable[..., Bus]) -> Iterator[dict]:
    port = free_port()
    settings = PtzSettings(instance="ptz1", state_hz=10, cameras={
        "ptz1": CameraConnection(url=f"http://127.0.0.1:{port}")}, timeout_s=0.3)
    node = Node("ptz", settings, make_bus())
    world = make_bus()
    states: list[m.PtzState] = []
    world.subscribe(keys.PTZ_STATE, states.append, latest=False, camera="ptz1")
    servers: list[CameraServer] = []
    thread = threading.Thread(target=run, args=(node,))
    ctx = {"port": port, "node": node, "world": world, "states": states, "servers": servers,
           "thread": thread, "calib": FakeCalib(make_bus())}
    yield ctx
    node.stop.set()
    thread.join(5)
    assert not thread.is_alive(), "the service stops when asked"
    for server in servers:
        server.close()


class FakeCalib:
    """What the calibration service is to a PTZ service: the pose its queryable answers with,
    and the news of each solve on the key."""

    def __init__(self, bus: Bus) -> None:
        self.bus = bus
        self.pose: m.CameraPose | None = None
        self.asked: list[float] = []  # when the PTZ service asked for the pose
        bus.serve_latest(keys.CALIB_POSE, self._answer, camera="ptz1")

    def _answer(self) -> m.CameraPose | None:
        self.asked.append(time.time())
        return self.pose

    def solve(self, **changes: float) -> m.CameraPose:
        self.pose = true_pose(time.time()).model_copy(update=changes)
        self.bus.publish(keys.CALIB_POSE, self.pose, camera="ptz1")
        return self.pose


def _publish_pose(service: dict) -> None:
    """The calibration service solves the true pose."""
    service["calib"].solve()


def _publish_robot(world: Bus, xyz: np.ndarray) -> None:
    world.publish(keys.TRACKER_ROBOT, m.RobotPosition(
        measured_s=time.time(), label="robot", x_mm=xyz[0], y_mm=xyz[1], z_mm=xyz[2],
        vx_mm_s=0.0, vy_mm_s=0.0, vz_mm_s=0.0))

def test_waits_for_a_pose_then_follows_the_robot(service: dict) -> None:
    service["servers"].append(_camera_server(service["port"]))
    service["thread"].start()
    world, states = service["world"], service["states"]

    def waiting() -> bool:  # the robot's samples come: no pose, no move
        _publish_robot(world, TARGET)
        return len(states) >= 3 and states[-1].status == "waiting_for_pose"

    wait_for(waiting, timeout=5, period=0.05)
    assert states[-1].pan_deg == 0.0 and states[-1].tilt_deg == 0.0, "no move without a pose"
    _publish_pose(service)

    def on_target() -> bool:
        _publish_robot(world, TARGET)
        last = states[-1]
        return last.status == "tracking" and last.aim_error_deg < 0.5

    wait_for(on_target, timeout=5, period=0.05)
    last = states[-1]
    assert aim_error_deg(TARGET, MOUNT, last.pan_deg, last.tilt_deg) < 0.5
    assert last.zoom == 1 and last.focal_px == pytest.approx(axis_215_px(3.8))


def test_previews_show_the_robot_near_the_image_centre_once_on_target(service: dict) -> None:
    service["node"].settings = service["node"].settings.model_copy(update={"preview_hz": 5.0})
    service["servers"].append(_camera_server(service["port"]))
    previews: list[m.PtzPreview] = []
    service["world"].subscribe(keys.PTZ_PREVIEW, previews.append, latest=False, camera="ptz1")
    service["thread"].start()
    wait_for(lambda: previews, timeout=5)
    assert previews[-1].robot_px is None, "no pose yet: no robot pixel"
    _publish_pose(service)

    def centred() -> bool:
        _publish_robot(service["world"], TARGET)
        last = previews[-1]
        return last.robot_px is not None and last.robot_px[0] == pytest.approx(
            last.width_px / 2, abs=10) and last.robot_px[1] == pytest.approx(
            last.height_px / 2, abs=10)

    wait_for(centred, timeout=8, period=0.1)
    last = previews[-1]
    image = cv2.imdecode(np.frombuffer(last.jpeg, np.uint8), cv2.IMREAD_GRAYSCALE)
    assert image is not None and image.shape == (last.height_px, last.width_px)
    assert [p.seq for p in previews] == sorted(p.seq for p in previews)


def test_late_start_gets_the_pose_by_query(service: dict, make_bus: Callable[..., Bus]) -> None:
    calib = make_bus()
    pose = m.CameraPose(measured_s=time.time(), camera="ptz1", x_mm=MOUNT.x_mm,
                        y_mm=MOUNT.y_mm, z_mm=MOUNT.z_mm, rx_deg=MOUNT.rx_deg,
                        ry_deg=MOUNT.ry_deg, rz_deg=MOUNT.rz_deg, focal_px=743.1,
                        mean_error_px=1.0, passpoints=100)
    calib.serve_latest(keys.CALIB_POSE, lambda: pose, camera="ptz1")
    wait_for(lambda: service["world"].query_latest(keys.CALIB_POSE, timeout_s=0.5,
                                                   camera="ptz1"))  # calib answers
    service["servers"].append(_camera_server(service["port"]))
    service["thread"].start()
    wait_for(lambda: service["states"] and service["states"][-1].status in ("idle", "tracking"))


def test_camera_away_is_reported_and_the_service_recovers(service: dict) -> None:
    service["thread"].start()
    states = service["states"]
    wait_for(lambda: states and states[-1].status == "camera_unreachable", timeout=5)
    assert service["node"].health().status == "degraded"
    assert "ptz1" in service["node"].health().detail
    service["servers"].append(_camera_server(service["port"]))
    _publish_pose(service)
    wait_for(lambda: states[-1].status in ("idle", "tracking"), timeout=10)
    assert service["thread"].is_alive()


def _aim_error(service: dict) -> float:
    _publish_robot(service["world"], TARGET)
    last = service["states"][-1]
    return aim_error_deg(TARGET, MOUNT, last.pan_deg, last.tilt_deg)


@pytest.mark.parametrize("version", [2**53, 2**53 - 1, 0])
def test_a_pose_put_on_the_key_is_never_taken_whatever_its_version(service: dict,
                                                                    version: int) -> None:
    """One pose message at version 2⁵³ used to mis-aim a camera for good: the calibration
    service could not out-version it. A message on the key is now only news; the pose is
    asked of the calibration service, whose stored pose is the truth."""
    service["servers"].append(_camera_server(service["port"]))
    service["thread"].start()
    world, states = service["world"], service["states"]
    wait_for(lambda: states)
    _publish_pose(service)
    wait_for(lambda: _aim_error(service) < 0.5 and states[-1].status == "tracking", timeout=5,
             period=0.05)
    spoof = service["calib"].pose.model_copy(update={
        "version": version, "rz_deg": MOUNT.rz_deg + 30.0, "measured_s": time.time()})
    spoofed_at = time.time()
    for _ in range(20):
        world.publish(keys.CALIB_POSE, spoof, camera="ptz1")
    # the news makes the PTZ service ask calib (within 0.6 s); half a second of states after
    # its answer, the robot coming all the while (the camera moves as it follows the robot)
    asked = wait_for(lambda: [t for t in service["calib"].asked if t > spoofed_at], timeout=5)

    def followed_after_the_answer() -> bool:
        _publish_robot(world, TARGET)
        return sum(s.measured_s > asked[0] for s in states) >= 5
    wait_for(followed_after_the_answer, timeout=5)
    since = [s for s in list(states) if s.measured_s > spoofed_at]
    worst = max(aim_error_deg(TARGET, MOUNT, s.pan_deg, s.tilt_deg) for s in since)
    assert worst < 0.5, f"the spoof moved the camera: {worst:.1f}° off in one of {len(since)}"
    service["calib"].solve(rz_deg=MOUNT.rz_deg + 0.5, version=1)  # a later solve, lower version
    wait_for(lambda: abs(_aim_error(service) - 0.5) < 0.3, timeout=5, period=0.05)


def test_answers_that_disagree_keep_the_pose_and_say_why(service: dict,
                                                         make_bus: Callable[..., Bus]) -> None:
    """A second queryable on the pose key (an open bus): its answer differs from the
    calibration service's, so the PTZ service takes neither and says so."""
    service["servers"].append(_camera_server(service["port"]))
    service["thread"].start()
    states, node = service["states"], service["node"]
    wait_for(lambda: states)
    true = service["calib"].solve()
    wait_for(lambda: _aim_error(service) < 0.5, timeout=5, period=0.05)
    rogue = make_bus()
    wrong = true.model_copy(update={"rz_deg": MOUNT.rz_deg + 30.0})
    rogue.serve_latest(keys.CALIB_POSE, lambda: wrong, camera="ptz1")
    rogue.publish(keys.CALIB_POSE, wrong, camera="ptz1")  # news: asked at once
    wait_for(lambda: "different poses answered" in node.health().detail, timeout=5)
    assert node.health().status == "degraded"
    assert _aim_error(service) < 0.5, "the pose it had stays"
