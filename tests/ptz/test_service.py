"""The PTZ service with the sim's camera over HTTP and a loopback bus (the test plays calib
and tracker by publishing a pose and robot positions)."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator

import cv2
import httpx
import numpy as np
import pytest

from common import keys
from common import messages as m
from common.bus import Bus
from common.camera import Pose
from common.lab_views import CameraConnection
from common.node import Node
from common.ptz_settings import PtzSettings
from services.ptz.aim import aim_error_deg
from services.ptz.service import run
from services.sim.camera_server import CameraServer, SimCamera
from services.sim.ptz import PtzHead
from tests.conftest import free_port, wait_for

MOUNT = Pose(3550, 1090, 2190, 180, 30, 165)
TARGET = np.array([-300.0, 200.0, 100.0])


def _camera_server(port: int, latency_s: float = 0.05, target: np.ndarray = TARGET
                   ) -> CameraServer:
    t0 = time.monotonic()
    sim = SimCamera("ptz1", PtzHead(MOUNT, latency_s=latency_s), lambda: target[None, :], [],
                    lambda: time.monotonic() - t0, np.random.default_rng(0))
    return CameraServer(sim, "127.0.0.1", port).start()


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
        bus.serve_latest(keys.CALIB_POSE, lambda: self.pose, camera="ptz1")

    def solve(self, **changes: float) -> m.CameraPose:
        self.pose = m.CameraPose(**{**dict(
            measured_s=time.time(), camera="ptz1", x_mm=MOUNT.x_mm, y_mm=MOUNT.y_mm,
            z_mm=MOUNT.z_mm, rx_deg=MOUNT.rx_deg, ry_deg=MOUNT.ry_deg, rz_deg=MOUNT.rz_deg,
            focal_mm=3.8, mean_error_px=1.0, passpoints=100), **changes})
        self.bus.publish(keys.CALIB_POSE, self.pose, camera="ptz1")
        return self.pose


def _publish_pose(service: dict) -> None:
    """The calibration service solves the true pose."""
    service["calib"].solve()


def _publish_robot(world: Bus, xyz: np.ndarray) -> None:
    world.publish(keys.TRACKER_ROBOT, m.RobotPosition(
        measured_s=time.time(), label="robot", x_mm=xyz[0], y_mm=xyz[1], z_mm=xyz[2],
        vx_mm_s=0.0, vy_mm_s=0.0, vz_mm_s=0.0))

def _following(service: dict, latency_s: float = 0.05, within_deg: float = 0.5,
               target: np.ndarray = TARGET) -> tuple[CameraServer, Callable[[], bool]]:
    """Start the service with a sim camera and the true pose; and the check that it follows
    the robot at ``target`` (a robot sample sent with each look)."""
    server = _camera_server(service["port"], latency_s, target)
    service["servers"].append(server)
    service["thread"].start()
    world, states = service["world"], service["states"]
    wait_for(lambda: states)  # the service is up and listening
    _publish_pose(service)

    def following() -> bool:
        _publish_robot(world, target)
        return bool(states) and states[-1].status == "tracking" and \
            states[-1].aim_error_deg < within_deg

    return server, following



def test_waits_for_a_pose_then_follows_the_robot(service: dict) -> None:
    service["servers"].append(_camera_server(service["port"]))
    service["thread"].start()
    world, states = service["world"], service["states"]
    for _ in range(10):
        _publish_robot(world, TARGET)
        time.sleep(0.05)  # the robot's samples at the tracker's 20 Hz: no pose, no move
    wait_for(lambda: states and states[-1].status == "waiting_for_pose")
    assert states[-1].pan_deg == 0.0 and states[-1].tilt_deg == 0.0, "no move without a pose"
    _publish_pose(service)

    def on_target() -> bool:
        _publish_robot(world, TARGET)
        last = states[-1]
        return last.status == "tracking" and last.aim_error_deg < 0.5

    wait_for(on_target, timeout=5, period=0.05)
    last = states[-1]
    assert aim_error_deg(TARGET, MOUNT, last.pan_deg, last.tilt_deg) < 0.5
    assert last.zoom == 1 and last.focal_mm == 3.8


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
    assert image.shape == (last.height_px, last.width_px)
    assert [p.seq for p in previews] == sorted(p.seq for p in previews)


def test_late_start_gets_the_pose_by_query(service: dict, make_bus: Callable[..., Bus]) -> None:
    calib = make_bus()
    pose = m.CameraPose(measured_s=time.time(), camera="ptz1", x_mm=MOUNT.x_mm,
                        y_mm=MOUNT.y_mm, z_mm=MOUNT.z_mm, rx_deg=MOUNT.rx_deg,
                        ry_deg=MOUNT.ry_deg, rz_deg=MOUNT.rz_deg, focal_mm=3.8,
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


def test_calibration_mode_holds_still_detects_and_ends_with_its_lease(service: dict) -> None:
    from common.camera import Intrinsics, head_pose, project

    server = _camera_server(service["port"])
    service["servers"].append(server)
    service["thread"].start()
    world, states = service["world"], service["states"]
    detections: list[m.MarkerDetections] = []
    snapshots: list[m.CameraFrame] = []
    world.subscribe(keys.PTZ_DETECTIONS, detections.append, latest=False, camera="ptz1")
    world.subscribe(keys.PTZ_SNAPSHOT, snapshots.append, latest=False, camera="ptz1")
    wait_for(lambda: states)
    held = (-4.0, 3.0)

    def renew() -> bool:  # as a collector does, until it has what it needs
        world.publish(keys.PTZ_CALIBRATION, m.CalibrationMode(
            measured_s=time.time(), camera="ptz1", active=True, pan_deg=held[0],
            tilt_deg=held[1], zoom=1, lease_s=1.0), camera="ptz1")
        return len(detections) >= 5

    wait_for(renew, timeout=10, period=0.3)
    assert server.camera.head.ir_cut_filter == "off"
    for action, values in (("move", {"pan_deg": 60.0, "tilt_deg": -20.0}),
                           ("nudge", {"pan_deg": 5.0}), ("preset", {"preset": "Home"})):
        world.publish(keys.PTZ_HAND, m.PtzHand(measured_s=time.time(), camera="ptz1",
                                               action=action, operator="olga (web h)",
                                               **values), camera="ptz1")
    seen = len(states)
    deadline = time.monotonic() + 1.5
    while time.monotonic() < deadline:  # a window: the page's moves must not happen
        renew()
        time.sleep(0.3)  # pacing the lease's renewals within the window
    during = states[seen:]
    assert during and all(abs(s.pan_deg - held[0]) < 0.1 and abs(s.tilt_deg - held[1]) < 0.1
                          for s in during), [(s.pan_deg, s.tilt_deg) for s in during]
    assert any(s.status == "calibrating" for s in states)
    expected = project(TARGET[None, :], head_pose(MOUNT, *held), Intrinsics(3.8))[0]
    for d in detections:  # none from before the camera stood where it was held
        (marker,) = d.markers
        assert abs(marker.u_px - expected[0]) < 1.0 and abs(marker.v_px - expected[1]) < 1.0
    assert {d.measured_s for d in detections} <= {s.measured_s for s in snapshots}
    assert snapshots[-1].encoding == "jpeg" and snapshots[-1].data[:2] == b"\xff\xd8"
    wait_for(lambda: states[-1].status == "waiting_for_pose", timeout=4)  # lease ran out
    assert server.camera.head.ir_cut_filter == "auto"
    count = len(detections)
    time.sleep(0.5)  # the subject: nothing more for half a second
    assert len(detections) == count, "no more snapshots once the mode has ended"


def test_a_pose_from_the_future_is_refused_and_cannot_mis_aim_the_camera(service: dict) -> None:
    """One pose with a wrong rotation stamped in the year 2096 used to win for good: ptz1's
    true aim error went from 0.1° to 60° until a restart, while it reported 'tracking'. Even
    from the calibration service's own answer it is refused."""
    service["servers"].append(_camera_server(service["port"]))
    service["thread"].start()
    world, states = service["world"], service["states"]
    wait_for(lambda: states)  # the service listens
    _publish_pose(service)

    def on_target() -> bool:
        _publish_robot(world, TARGET)
        return bool(states) and states[-1].status == "tracking"

    wait_for(on_target, timeout=5, period=0.05)
    node: Node = service["node"]
    pose_key = keys.CALIB_POSE.key(node.bus.prefix, camera="ptz1")
    service["calib"].solve(measured_s=4e9, ry_deg=MOUNT.ry_deg - 40.0,
                           rz_deg=MOUNT.rz_deg + 50.0)
    wait_for(lambda: node.health().keys[pose_key].dropped.get("from_future", 0) >= 1,
             timeout=5)
    for _ in range(10):
        _publish_robot(world, TARGET)
        time.sleep(0.05)  # half a second of samples at 20 Hz: the refused pose must not act
    last = states[-1]
    assert aim_error_deg(TARGET, MOUNT, last.pan_deg, last.tilt_deg) < 0.5, "the true aim"


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
    for _ in range(20):
        world.publish(keys.CALIB_POSE, spoof, camera="ptz1")
    quiet_until = time.monotonic() + 1.0  # the PTZ service asks calib within 0.6 s
    while time.monotonic() < quiet_until:
        assert _aim_error(service) < 0.5, "the spoof did not move the camera"
        time.sleep(0.05)  # the subject: a second in which nothing moves
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
    true = _publish_pose(service) or service["calib"].pose
    wait_for(lambda: _aim_error(service) < 0.5, timeout=5, period=0.05)
    rogue = make_bus()
    wrong = true.model_copy(update={"rz_deg": MOUNT.rz_deg + 30.0})
    rogue.serve_latest(keys.CALIB_POSE, lambda: wrong, camera="ptz1")
    rogue.publish(keys.CALIB_POSE, wrong, camera="ptz1")  # news: asked at once
    wait_for(lambda: "different poses answered" in node.health().detail, timeout=5)
    assert node.health().status == "degraded"
    assert _aim_error(service) < 0.5, "the pose it had stays"


def test_a_wrong_pose_is_caught_by_the_pointing_check(service: dict) -> None:
    """A pose with a wrong rotation (as a poisoned pose message would bring) points the
    camera away from the robot while its own aim error stays small; the infrared previews
    show it: one at once for the new pose, then one every ``pointing_confirm_s`` (0.7 s
    here) while they disagree — though the check's own period is the default 5 minutes, so
    the filter moves only for these."""
    node, states = service["node"], service["states"]
    node.settings = node.settings.model_copy(update={"preview_hz": 5.0,
                                                     "pointing_confirm_s": 0.7})
    assert node.settings.pointing_infrared_s == 300.0
    server = _camera_server(service["port"])
    service["servers"].append(server)
    service["thread"].start()
    wait_for(lambda: states, timeout=5)  # subscribed by now
    _publish_pose(service)

    def judged(predicate: Callable[[m.PtzState], bool]) -> bool:
        _publish_robot(service["world"], TARGET)
        return bool(states) and predicate(states[-1])

    wait_for(lambda: judged(lambda s: s.pointing_error_deg is not None
                            and s.pointing_error_deg < 1.0), timeout=8, period=0.1)
    assert states[-1].pointing_problem == "" and node.health().status == "ok"
    wrong = m.CameraPose(measured_s=time.time(), camera="ptz1", x_mm=MOUNT.x_mm,
                         y_mm=MOUNT.y_mm, z_mm=MOUNT.z_mm, rx_deg=MOUNT.rx_deg,
                         ry_deg=MOUNT.ry_deg, rz_deg=MOUNT.rz_deg + 40, focal_mm=3.8,
                         mean_error_px=0.2, passpoints=100)
    service["calib"].pose = wrong  # a wrong solve, as a poisoned store would give
    service["world"].publish(keys.CALIB_POSE, wrong, camera="ptz1")
    poisoned_at = time.monotonic()
    wait_for(lambda: judged(lambda s: s.pointing_problem.startswith("pointing:")), timeout=15,
             period=0.1)
    print(f"wrong pose reported after {time.monotonic() - poisoned_at:.1f} s: "
          f"{states[-1].pointing_problem}")
    assert states[-1].aim_error_deg < 1.0, "the pose's own aim error cannot see it"
    health = node.health()
    assert health.status == "degraded" and health.detail.startswith("pointing:")
    assert "the pose asked of calib again" in health.detail
    service["calib"].pose = service["calib"].pose.model_copy(update={
        "rz_deg": MOUNT.rz_deg, "measured_s": time.time()})  # put right at the source: the
    # PTZ service asks again every few seconds while its pictures disagree, and takes it
    wait_for(lambda: judged(lambda s: s.pointing_problem == ""), timeout=8, period=0.1)
    assert node.health().status == "ok"
    head = server.camera.head
    seen: list[tuple[float, int]] = []  # the right pose's own check done: no move for 2 s

    def settled() -> bool:
        _publish_robot(service["world"], TARGET)
        seen.append((time.monotonic(), head.ir_cut_moves))
        return seen[-1][0] - next(t for t, n in seen if n == seen[-1][1]) >= 2.0

    wait_for(settled, timeout=15, period=0.1)
    moves = head.ir_cut_moves
    assert 2 * 4 <= moves <= 2 * 12, f"the filter moved {moves} times"  # out and in, each
    start = time.monotonic()  # agreeing now: the next check is minutes away
    while time.monotonic() - start < 3.0:  # "nothing happens" window: 4 × confirm_s
        _publish_robot(service["world"], TARGET)
        time.sleep(0.1)  # pacing the robot samples in a window where no switch may come
    assert head.ir_cut_moves == moves


def test_the_filter_is_left_alone_while_a_recording_runs(service: dict,
                                                         make_bus: Callable[..., Bus]) -> None:
    """A recording's liveliness token (``stb record`` holds one): a new pose is not checked
    in infrared while it is there; once it goes, the check comes at the next preview."""
    node = service["node"]
    node.settings = node.settings.model_copy(update={"preview_hz": 5.0})
    recorder = make_bus()
    token = recorder.session.liveliness().declare_token(
        keys.recording_key(recorder.prefix, "host-1234"))
    server = _camera_server(service["port"])
    service["servers"].append(server)
    service["thread"].start()
    wait_for(lambda: service["states"], timeout=5)
    _publish_pose(service)
    wait_for(lambda: service["states"][-1].status == "tracking" or
             _publish_robot(service["world"], TARGET), timeout=5, period=0.1)
    start = time.monotonic()
    while time.monotonic() - start < 2.0:  # "nothing happens" window: 10 previews at 5 Hz
        _publish_robot(service["world"], TARGET)
        time.sleep(0.1)  # pacing the robot samples in a window where no switch may come
    assert server.camera.head.ir_cut_moves == 0, "switched while recording"
    token.undeclare()
    wait_for(lambda: server.camera.head.ir_cut_moves >= 2, timeout=5, period=0.1)


def test_a_move_by_someone_else_pauses_following_then_it_follows_again(service: dict) -> None:
    """Frigate's manual override: the camera moved by another client is left alone for
    ``manual_pause_s`` (status manual), then the service takes it back to the robot."""
    service["node"].settings = service["node"].settings.model_copy(
        update={"manual_pause_s": 2.0})
    server, following = _following(service)
    world, states = service["world"], service["states"]
    wait_for(following, timeout=5, period=0.05)
    with httpx.Client(base_url=f"http://127.0.0.1:{server.port}", timeout=2,
                      auth=httpx.DigestAuth("root", "pass")) as operator:
        operator.get("/axis-cgi/com/ptz.cgi", params={"rpan": "30", "rtilt": "-10"})
    moved_at = time.monotonic()

    def manual() -> bool:
        _publish_robot(world, TARGET)
        return states[-1].status == "manual"

    wait_for(manual, timeout=2, period=0.05)
    during = []
    while time.monotonic() - moved_at < 1.5:  # the robot's samples keep coming: left alone
        _publish_robot(world, TARGET)
        during.append(states[-1])
        time.sleep(0.05)  # samples at 20 Hz for 1.5 s, in which it must be left alone
    assert all(s.aim_error_deg > 10 for s in during[-10:]), "left where it was put"
    wait_for(following, timeout=5, period=0.05)
    assert time.monotonic() - moved_at >= 2.0, "the pause lasted"


def test_a_camera_that_reboots_is_not_taken_for_a_hand(service: dict) -> None:
    """The camera goes away and comes back at its home position (a reboot; the sim's
    restart), 26° off where it looked: not "manual" (it once paused following for 30 s,
    11–15° off), it follows again at once."""
    far_side = np.array([0.0, -2500.0, 0.0])
    assert aim_error_deg(far_side, MOUNT, 0.0, 0.0) > 20.0
    server, following_first = _following(service, target=far_side)
    world, states = service["world"], service["states"]
    wait_for(following_first, timeout=5, period=0.05)
    since = states[-1].measured_s  # the first move (from home) counts as ours for 1 s more
    wait_for(lambda: following_first() and states[-1].measured_s > since + 1.2, timeout=5,
             period=0.05)
    there = far_side + [300.0, 0.0, 0.0]  # a step on: our path spans no more of home

    def following() -> bool:
        _publish_robot(world, there)
        return states[-1].status == "tracking" and states[-1].aim_error_deg < 0.5

    wait_for(following, timeout=5, period=0.05)
    server.close()
    wait_for(lambda: states[-1].status == "camera_unreachable", timeout=5,
             why=lambda: str([s.status for s in states[-5:]]))
    rebooted = len(states)
    service["servers"].append(_camera_server(service["port"], target=there))  # at home
    wait_for(following, timeout=10, period=0.05,
             why=lambda: str(sorted({s.status for s in states[rebooted:]})))
    assert "manual" not in {s.status for s in states[rebooted:]}


def test_an_operators_hand_holds_moves_and_releases_the_camera(service: dict) -> None:
    """From the page (stb/ptz/{camera}/hand): held, the camera follows no more and its own
    moves are not someone else's; moved by hand and to a preset; released, it follows."""
    server, following = _following(service)
    world, states = service["world"], service["states"]

    def hand(action: str, **values: object) -> None:
        world.publish(keys.PTZ_HAND, m.PtzHand(measured_s=time.time(), camera="ptz1",
                                               action=action, operator="olga (web h)",
                                               **values), camera="ptz1")

    wait_for(following, timeout=5, period=0.05)
    assert "Home" in states[-1].presets, "the camera's own presets"
    hand("hold")
    wait_for(lambda: states[-1].status == "held" and states[-1].held_by == "olga (web h)",
             timeout=3)
    hand("move", pan_deg=-150.0, tilt_deg=-20.0, zoom=2000)

    def at(pan: float, tilt: float) -> bool:
        _publish_robot(world, TARGET)  # the robot's samples keep coming: it stays held
        return abs(states[-1].pan_deg - pan) < 0.5 and abs(states[-1].tilt_deg - tilt) < 0.5

    wait_for(lambda: at(-150.0, -20.0), timeout=5, period=0.05)
    assert states[-1].status == "held", "its own move is no one else's hand"
    hand("nudge", pan_deg=-5.0, tilt_deg=5.0)
    wait_for(lambda: at(-155.0, -15.0), timeout=5, period=0.05)
    hand("preset", preset="Home")
    wait_for(lambda: at(0.0, 0.0), timeout=5, period=0.05)
    hand("follow")
    wait_for(following, timeout=5, period=0.05)
    assert states[-1].held_by == ""


@pytest.mark.system
def test_a_flood_of_calibration_requests_never_makes_its_own_moves_someone_elses(
        service: dict) -> None:
    """3,000 valid calibration-mode requests in a few seconds (on and off, random holds, short
    leases): the service's own calibration moves, queued in the camera, are never taken for
    someone else's hand; once the flood ends the camera follows the robot again."""
    service["node"].settings = service["node"].settings.model_copy(update={"state_hz": 5.0})
    _, following = _following(service, PtzHead.latency_s, within_deg=1.0)  # the sim's own
    world, states = service["world"], service["states"]

    wait_for(following, timeout=5, period=0.05)
    rng = np.random.default_rng(5)
    flood_start = len(states)
    for i in range(3000):
        world.publish(keys.PTZ_CALIBRATION, m.CalibrationMode(
            measured_s=time.time(), camera="ptz1", active=bool(i % 7),
            pan_deg=float(rng.uniform(-180, 180)), tilt_deg=float(rng.uniform(-90, 0)),
            zoom=int(rng.integers(1, 9999)), lease_s=3.0), camera="ptz1")
        if i % 100 == 0:
            _publish_robot(world, TARGET)
            time.sleep(0.1)  # 3,000 in about 3 s, the robot's samples among them
    wait_for(following, timeout=10, period=0.05,
             why=lambda: f"last state {states[-1].status}, {states[-1].aim_error_deg:.1f}°")
    statuses = {s.status for s in states[flood_start:]}
    assert "manual" not in statuses, statuses
