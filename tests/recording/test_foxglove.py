"""Foxglove's typed view of the lab: the scene from bus messages (pure), and ``stb foxglove``
serving it live to a WebSocket client speaking Foxglove's protocol, decoded by the schemas the
server advertises."""

from __future__ import annotations

import asyncio
import base64
import json
import math
import struct
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import websockets
from websockets.typing import Subprotocol

from common import keys
from common import messages as m
from common.bus import Bus
from common.camera import Pose, head_pose
from services.recording.typed import CRATER, SCENE, TF, LabScene, Typed, crater_mesh
from services.sim.world import CraterShape, generate_crater
from tests.calib.test_demo_calibration import MOUNTS
from tests.conftest import stb_process, wait_for
from tests.ports import free_port, listening
from tests.recording.typed import message_class
from tests.services.test_processes import _stop


def _decode(typed: Typed) -> Any:  # a protobuf message of its schema
    return message_class(typed.schema_name, typed.schema_data).FromString(typed.data)


def _robot(t: float, x: float = 1000.0) -> m.RobotPosition:
    return m.RobotPosition(measured_s=t, x_mm=x, y_mm=-500.0, z_mm=120.0, vx_mm_s=100.0,
                           vy_mm_s=0.0, vz_mm_s=0.0)


def _crane(t: float) -> m.CraneState:
    return m.CraneState(measured_s=t, status="tracking", x_mm=1100.0, y_mm=-500.0,
                        target_x_mm=1100.0, target_y_mm=-500.0, enabled=True, moving=True,
                        fault_bits=0, mode="armed")


def _offload(t: float, warning: bool) -> m.GravityOffload:
    return m.GravityOffload(measured_s=t, horizontal_error_mm=100.0, cable_length_mm=2000.0,
                            vertical_loss_pct=0.1, horizontal_share_pct=5.0, warning=warning,
                            warn_above_pct=4.0)


def _pose(camera: str = "ptz1") -> m.CameraPose:
    return m.CameraPose(measured_s=1.0, camera=camera, **MOUNTS[camera].fields(), focal_px=743.1,
                        mean_error_px=1.0, passpoints=90)


def _ptz(t: float, camera: str = "ptz1") -> m.PtzState:
    return m.PtzState(measured_s=t, camera=camera, status="tracking", pan_deg=-12.0,
                      tilt_deg=-8.0, zoom=1, focal_px=743.1, aim_error_deg=0.2)


def _entities(out: list[Typed], topic: str = SCENE) -> dict[str, Any]:
    return {e.id: e for t in out if t.topic == topic for e in _decode(t).entities}


def test_robot_crane_and_cable_in_metres_the_cable_red_above_the_limit() -> None:
    scene = LabScene()
    scene.on(_offload(9.0, warning=True))
    scene.on(_crane(9.5))
    out = scene.on(_robot(10.0))
    entities = _entities(out)
    robot = entities["robot"].spheres[0].pose.position
    assert (robot.x, robot.y, robot.z) == pytest.approx((1.0, -0.5, 0.12))
    crane = entities["crane"]
    assert crane.cubes[0].pose.position.z == pytest.approx(0.12 + 2.0), "the cable's length up"
    cable = crane.lines[0]
    assert cable.color.r == 1.0 and cable.color.b < 0.5, "red: the pull is above the limit"
    assert [c for p in cable.points for c in (p.x, p.y)] == pytest.approx([1.1, -0.5, 1.0, -0.5])
    assert "100 mm off" in crane.texts[0].text
    frames = {f.child_frame_id: f for t in out if t.topic == TF for f in _decode(t).transforms}
    assert frames["robot"].translation.x == pytest.approx(1.0)


def test_the_scene_is_sent_at_most_scene_hz() -> None:
    scene = LabScene(scene_hz=10.0)
    sent = sum(any(t.topic == SCENE for t in scene.on(_robot(100.0 + i * 0.001)))
               for i in range(1000))  # one second at 1000 Hz
    assert sent == 10


def test_a_camera_transform_is_its_head_pose_and_its_cone_is_in_its_frame() -> None:
    scene = LabScene()
    scene.on(_pose())
    out = scene.on(_ptz(2.0))
    [transform] = [f for t in out if t.topic == TF for f in _decode(t).transforms]
    head = head_pose(Pose.of(_pose()), -12.0, -8.0)
    assert transform.parent_frame_id == "world" and transform.child_frame_id == "ptz1"
    assert [transform.translation.x, transform.translation.y, transform.translation.z] == \
        pytest.approx(head.position / 1000)
    q = transform.rotation
    w, x, y, z = q.w, q.x, q.y, q.z
    rotation = np.array([  # the quaternion back to a matrix
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    assert rotation == pytest.approx(head.rotation, abs=1e-9)
    cone = _entities(scene.on(_robot(2.1)))["camera/ptz1"]
    assert cone.frame_id == "ptz1" and len(cone.lines[0].points) == 16
    far = [p for p in cone.lines[0].points if p.x > 0]
    half_width = math.degrees(math.atan(max(abs(p.y) for p in far) / far[0].x))
    assert half_width == pytest.approx(math.degrees(math.atan(1.8 / 3.8)), abs=0.01), \
        "the 1/4-inch chip's half width (1.8 mm) at 3.8 mm"


def test_a_preview_becomes_an_image_and_its_annotations() -> None:
    jpeg = b"\xff\xd8 a jpeg"
    preview = m.PtzPreview(measured_s=3.0, camera="ptz2", seq=4, width_px=704, height_px=576,
                           jpeg=jpeg, pan_deg=0, tilt_deg=0, robot_px=[350.0, 290.0],
                           markers=[m.DetectedMarker(
                               u_px=351.0, v_px=289.0, radius_long_px=3.0, radius_short_px=3.0,
                               angle_deg=0.0, roundness=1.0, area_px=28)])
    out = {t.topic: _decode(t) for t in LabScene().on(preview)}
    image = out["/ptz2/image"]
    assert image.data == jpeg and image.format == "jpeg" and image.frame_id == "ptz2"
    annotations = out["/ptz2/annotations"]
    assert [(c.position.x, c.position.y) for c in annotations.circles] == [(351.0, 289.0)]
    assert len(annotations.points[0].points) == 4, "a cross where the robot should be"


def test_the_crater_mesh_follows_the_height_map() -> None:
    height_map = generate_crater(CraterShape(), np.random.default_rng(2))
    mesh = _decode(crater_mesh(height_map, 1.0)).entities[0].triangles[0]
    n = int(round(math.sqrt(len(mesh.points))))
    assert n * n == len(mesh.points) and n <= 81 and len(mesh.indices) == (n - 1) ** 2 * 6
    for p in mesh.points[:: 97]:
        assert p.z * 1000 == pytest.approx(height_map.height_at(p.x * 1000, p.y * 1000),
                                           abs=1.0)
    assert len(mesh.colors) == len(mesh.points)
    scene = LabScene(height_map, crater_every_s=60.0)
    crater_at = [t.time_s for i in range(130) for t in scene.on(_robot(float(i)))
                 if t.topic == CRATER]
    assert crater_at == [0.0, 60.0, 120.0]


SERVER_INFO = "(server info)"


async def _client(url: str, topics: set[str], until: Callable[[dict, dict], bool],
                  timeout_s: float) -> tuple[dict[str, dict], dict[str, list[bytes]]]:
    """A Foxglove WebSocket client: reads the advertised channels, subscribes to ``topics``,
    collects their messages until ``until(advertised, messages)`` or for ``timeout_s`` (then
    the caller's assertions say what did not come). An error status from the server fails."""
    advertised: dict[str, dict] = {}
    got: dict[str, list[bytes]] = {}
    by_subscription: dict[int, str] = {}
    async with websockets.connect(url, subprotocols=[Subprotocol("foxglove.sdk.v1"),
                                                     Subprotocol("foxglove.websocket.v1")]) as ws:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline and not until(advertised, got):
            try:
                frame = await asyncio.wait_for(ws.recv(), timeout=deadline - time.monotonic())
            except TimeoutError:
                break
            if isinstance(frame, str):
                op = json.loads(frame)
                assert not (op.get("op") == "status" and op.get("level") == 2), op
                if op.get("op") == "serverInfo":
                    advertised[SERVER_INFO] = op
                if op.get("op") == "advertise":
                    new = []
                    for channel in op["channels"]:
                        advertised[channel["topic"]] = channel
                        if channel["topic"] in topics:
                            sub = len(by_subscription) + 1
                            by_subscription[sub] = channel["topic"]
                            new.append({"id": sub, "channelId": channel["id"]})
                    if new:
                        await ws.send(json.dumps({"op": "subscribe", "subscriptions": new}))
            elif frame[0] == 1:  # message data: subscription, log time, payload
                sub, _ = struct.unpack_from("<IQ", frame, 1)
                got.setdefault(by_subscription[sub], []).append(frame[13:])
    return advertised, got


def test_stb_foxglove_serves_the_typed_scene_images_and_json_series(
        make_bus: Callable[..., Bus], router_endpoint: str, tmp_path: Path) -> None:
    crater_file = tmp_path / "crater.npz"
    generate_crater(CraterShape(), np.random.default_rng(1)).save(crater_file)
    port = free_port()
    bus = make_bus()
    # the pose was published before the bridge started: it asks the calib's queryable for it
    bus.serve_latest(keys.CALIB_POSE, _pose, camera="ptz1")
    proc = stb_process("foxglove", "--connect", router_endpoint, "--set", f"port={port}",
                       "--set", f"height_map={crater_file}", "--set", "bus.zenoh.listen=[]",
                       "--set", 'allowed_origins=["https://app.foxglove.dev"]')
    try:
        wait_for(lambda: proc.poll() is not None or listening(port), timeout=20, period=0.2)
        assert proc.poll() is None, proc.stderr.read()
        stop = False

        async def publish() -> None:
            i = 0
            while not stop:
                t = time.time()
                bus.publish(keys.TRACKER_ROBOT, _robot(t, x=1000.0 + i))
                bus.publish(keys.GANTRY_STATE, _crane(t))
                bus.publish(keys.GANTRY_OFFLOAD, _offload(t, warning=False))
                bus.publish(keys.PTZ_STATE, _ptz(t), camera="ptz1")
                i += 1
                await asyncio.sleep(0.05)  # paces the published messages (20 Hz)

        async def run() -> tuple[dict, dict]:
            nonlocal stop
            task = asyncio.create_task(publish())
            url, wanted = f"ws://127.0.0.1:{port}", {SCENE, CRATER, TF, "json/stb/gantry/offload"}
            try:
                # foxglove-sdk can refuse a subscription ("Unknown channel ID") to a channel made
                # while the client connects (docs/operator.md, Foxglove): a first client waits
                # until the channels exist, the second subscribes
                await _client(url, set(), lambda advertised, _: wanted <= set(advertised),
                              timeout_s=25)
                return await _client(
                    url, wanted, lambda _, got: all(len(got.get(t, [])) >= 2 for t in (SCENE, TF))
                    and CRATER in got and "json/stb/gantry/offload" in got, timeout_s=25)
            finally:
                stop = True
                await task

        advertised, got = asyncio.run(run())
        origins = {origin: asyncio.run(_handshake(f"ws://127.0.0.1:{port}", origin))
                   for origin in ("https://evil.example", "http://localhost:8080",
                                  "https://app.foxglove.dev", "http://127.0.0.1.evil.example")}
    finally:
        assert _stop(proc, 2, timeout=15) == 0
    assert origins == {"https://evil.example": 403, "http://localhost:8080": 101,
                       "https://app.foxglove.dev": 101, "http://127.0.0.1.evil.example": 403}, \
        "a foreign web page cannot read the bus; this machine's and the configured can"
    counts = {topic: len(messages) for topic, messages in got.items()}
    assert {SCENE, TF, CRATER, "json/stb/gantry/offload"} <= set(got), (sorted(advertised),
                                                                        counts)
    assert advertised[SCENE]["schemaName"] == "foxglove.SceneUpdate"
    granted = set(advertised[SERVER_INFO].get("capabilities", []))
    assert not granted & {"clientPublish", "services", "parameters", "connectionGraph"}, \
        "nothing from Foxglove's clients reaches the bus"
    assert advertised[SCENE]["encoding"] == "protobuf"
    assert advertised[TF]["schemaName"] == "foxglove.FrameTransforms"
    series = advertised["json/stb/gantry/offload"]
    assert series["encoding"] == "json" and series["schemaName"] == "stb.GravityOffload"
    assert "horizontal_error_mm" in json.loads(series["schema"])["properties"]

    def decoded(topic: str, payload: bytes) -> Any:
        schema = base64.b64decode(advertised[topic]["schema"])
        return message_class(advertised[topic]["schemaName"], schema).FromString(payload)

    scenes = [decoded(SCENE, p) for p in got[SCENE]]
    robot = next(e for s in scenes for e in s.entities if e.id == "robot")
    assert robot.spheres[0].pose.position.y == pytest.approx(-0.5)
    assert robot.spheres[0].pose.position.x >= 1.0
    frames = {f.child_frame_id for p in got[TF] for f in decoded(TF, p).transforms}
    assert {"ptz1", "robot", "crane"} <= frames
    mesh = decoded(CRATER, got[CRATER][0]).entities[0].triangles[0]
    assert len(mesh.points) > 1000, "the crater sent to the client that subscribed"
    offload = json.loads(got["json/stb/gantry/offload"][0])
    assert offload["horizontal_error_mm"] == 100.0 and offload["warn_above_pct"] == 4.0


async def _handshake(url: str, origin: str) -> int:
    """The HTTP status of a WebSocket handshake that a page at ``origin`` makes (101: open);
    an open connection gets its server info, relayed from foxglove-sdk's server."""
    try:
        async with websockets.connect(url, origin=origin,  # type: ignore[arg-type]
                                      subprotocols=["foxglove.sdk.v1"]) as ws:  # type: ignore[list-item]
            assert json.loads(await asyncio.wait_for(ws.recv(), 5))["op"] == "serverInfo"
            return 101
    except websockets.InvalidStatus as err:
        return err.response.status_code
