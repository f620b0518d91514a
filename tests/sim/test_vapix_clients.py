"""The simulated cameras as third-party clients use them: Home Assistant's AXIS library
(``axis``), a browser's MJPEG stream, raw VAPIX requests, all over real HTTP with Digest."""

from __future__ import annotations

import ast
import asyncio
import time
from collections.abc import Awaitable, Callable, Iterator
from pathlib import Path
from typing import TypeVar

import cv2
import httpx
import numpy as np
import pytest
from axis.device import AxisDevice
from axis.interfaces.ptz import PtzControl
from axis.models.configuration import Configuration
from axis.models.ptz_cgi import PtzQuery
from axis.models.pwdgrp_cgi import SecondaryGroup

from services.sim.camera_server import CameraServer, SimCamera
from services.sim.lab import Lab
from services.sim.vapix_device import serial_of
from tests.conftest import poll_async, wait_for

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def camera(lab: Lab) -> Iterator[tuple[CameraServer, httpx.Client]]:
    cam, t0 = lab.settings.cameras[0], time.monotonic()
    sim = SimCamera(cam.name, lab.heads[cam.name], lambda _t: lab.bright_points(0.0),
                    lab.ptz_glints, lambda: time.monotonic() - t0, np.random.default_rng(0),
                    cam.user, cam.password)
    server = CameraServer(sim, "127.0.0.1", 0).start()
    client = httpx.Client(base_url=f"http://127.0.0.1:{server.port}", timeout=5,
                          auth=httpx.DigestAuth(cam.user, cam.password))
    yield server, client
    client.close()
    server.close()


T = TypeVar("T")


def _with_axis(server: CameraServer, work: Callable[[AxisDevice], Awaitable[T]]) -> T:
    async def run() -> T:
        async with httpx.AsyncClient() as session:
            device = AxisDevice(Configuration(session, "127.0.0.1", port=server.port,
                                              username=server.camera.user,
                                              password=server.camera.password))
            return await work(device)
    return asyncio.run(asyncio.wait_for(run(), 30))


def _pairs(body: bytes) -> dict[str, str]:
    return dict(line.split("=", 1) for line in body.decode().split() if "=" in line)


def test_the_axis_library_identifies_the_camera(camera: tuple, lab: Lab) -> None:
    server, _ = camera

    async def identify(device: AxisDevice) -> AxisDevice:
        await device.vapix.initialize()
        await device.vapix.initialize_users()
        await device.vapix.load_user_groups()
        return device

    vapix = _with_axis(server, identify).vapix
    assert vapix.product_number == "215 PTZ"
    assert vapix.product_type == "PTZ Network Camera"
    assert vapix.serial_number == serial_of(server.camera.name) != ""
    assert vapix.firmware_version.endswith("-sim")
    assert vapix.access_rights is SecondaryGroup.ADMIN_PTZ
    assert vapix.params.property_handler["0"].ptz is True
    assert vapix.params.ptz_handler.supported and vapix.params.ptz_handler.initialized
    ptz = vapix.params.ptz_handler["0"]
    limits, head = ptz.limits["1"], lab.heads[server.camera.name].limits
    assert (limits.min_pan, limits.max_pan, limits.min_tilt, limits.max_tilt) == (
        head.min_pan, head.max_pan, head.min_tilt, head.max_tilt)
    assert (limits.min_zoom, limits.max_zoom) == (head.min_zoom, head.max_zoom)
    support = ptz.support["1"]
    assert support.absolute_pan and support.server_preset and support.auto_focus
    assert not support.area_zoom  # what the sim does not do, it does not claim
    assert [p.id for p in vapix.streaming_profiles] == ["Quality", "Bandwidth"]
    assert sorted(vapix.ports.keys()) == ["0", "1"]


def test_the_axis_library_moves_the_camera_and_reads_it_back(camera: tuple) -> None:
    server, _ = camera

    async def reaching(ptz: PtzControl, pan: float, tilt: float, zoom: int) -> bytes:
        """The position once it is the one asked for (or what it is after 10 s)."""
        async def there() -> bytes | None:
            now = await ptz.query(PtzQuery.POSITION)
            at = _pairs(now)
            return now if (float(at["pan"]), float(at["tilt"]), int(at["zoom"])) == \
                (pan, tilt, zoom) else None

        return await poll_async(there, 10, 0.05) or await ptz.query(PtzQuery.POSITION)

    async def move(device: AxisDevice) -> tuple[bytes, bytes, bytes]:
        ptz = device.vapix.ptz
        await ptz.control(pan=30.0, tilt=-10.0, zoom=2000, speed=100)
        moved = await reaching(ptz, 30.0, -10.0, 2000)
        await ptz.control(go_to_server_preset_name="Home")
        home = await reaching(ptz, 0.0, 0.0, 1)
        return moved, home, await ptz.query(PtzQuery.LIMITS)

    moved, home, limits = _with_axis(server, move)
    at = _pairs(moved)
    assert (float(at["pan"]), float(at["tilt"]), int(at["zoom"])) == (30.0, -10.0, 2000)
    back = _pairs(home)
    assert (float(back["pan"]), float(back["tilt"]), int(back["zoom"])) == (0.0, 0.0, 1)
    assert _pairs(limits)["MaxPan"] == f"{server.camera.head.limits.max_pan:g}"


def _at(client: httpx.Client) -> tuple[float, float]:
    at = _pairs(client.get("/axis-cgi/com/ptz.cgi", params={"query": "position"}).content)
    return float(at["pan"]), float(at["tilt"])


def test_server_presets_set_list_go_and_remove(camera: tuple) -> None:
    _, client = camera
    ptz = "/axis-cgi/com/ptz.cgi"
    assert client.get(ptz, params={"pan": "45", "tilt": "-20"}).status_code == 204
    wait_for(lambda: _at(client) == (45.0, -20.0), timeout=5, why=lambda: str(_at(client)))
    assert client.get(ptz, params={"setserverpresetname": "crater rim"}).status_code == 204
    listed = client.get(ptz, params={"query": "presetposall"}).text.splitlines()
    assert listed == ["Preset Positions for camera 1", "presetposno1=Home",
                      "presetposno2=crater rim"]
    client.get(ptz, params={"move": "home"})
    wait_for(lambda: _at(client) == (0.0, 0.0), timeout=5, why=lambda: str(_at(client)))
    assert client.get(ptz, params={"gotoserverpresetno": "2"}).status_code == 204
    wait_for(lambda: _at(client) == (45.0, -20.0), timeout=5, why=lambda: str(_at(client)))
    assert client.get(ptz, params={"removeserverpresetname": "crater rim"}).status_code == 204
    refused = client.get(ptz, params={"gotoserverpresetname": "crater rim"})
    assert refused.status_code == 200 and refused.text.startswith("Error:")
    params = client.post("/axis-cgi/param.cgi", data={"action": "list",
                                                      "group": "root.PTZ.Preset"}).text
    assert "Position.P1.Name=Home" in params and "crater rim" not in params


def test_focus_by_hand_turns_autofocus_off_and_on_again(camera: tuple) -> None:
    _, client = camera
    ptz = "/axis-cgi/com/ptz.cgi"
    assert _pairs(client.get(ptz, params={"query": "position"}).content)["autofocus"] == "on"
    assert client.get(ptz, params={"focus": "1234"}).status_code == 204
    at = _pairs(client.get(ptz, params={"query": "position"}).content)
    assert (at["focus"], at["autofocus"]) == ("1234", "off")
    assert client.get(ptz, params={"autofocus": "on"}).status_code == 204
    assert _pairs(client.get(ptz, params={"query": "position"}).content)["autofocus"] == "on"
    assert client.get(ptz, params={"autofocus": "maybe"}).text.startswith("Error:")


def test_the_mjpeg_stream_paces_whole_jpegs(camera: tuple) -> None:
    _, client = camera
    started = time.monotonic()
    with client.stream("GET", "/axis-cgi/mjpg/video.cgi",
                       params={"fps": "5", "nbrofframes": "4", "resolution": "352x288"}) as reply:
        assert reply.status_code == 200
        kind = reply.headers["content-type"]
        assert kind.startswith("multipart/x-mixed-replace")
        body = reply.read()
    elapsed = time.monotonic() - started
    boundary = kind.split("boundary=")[1].encode()
    parts = [p for p in body.split(b"--" + boundary) if p.strip()]
    assert len(parts) == 4
    for part in parts:
        head, _, jpeg = part.partition(b"\r\n\r\n")
        length = int(_pairs(head.replace(b": ", b"="))["Content-Length"])
        image = cv2.imdecode(np.frombuffer(jpeg[:length], np.uint8), cv2.IMREAD_GRAYSCALE)
        assert image is not None and image.shape == (288, 352)
    assert elapsed >= 3 / 5 - 0.05, f"4 frames at 5 fps came in {elapsed:.2f} s"


@pytest.mark.parametrize(("path", "kind", "payload", "expect"), [
    ("/axis-cgi/param.cgi", "form", {"action": "list", "group": "root.Nothing"},
     "# Error: Error -1 getting param in group 'root.Nothing'"),
    ("/axis-cgi/param.cgi", "form", {"action": "update", "root.Brand.Brand": "x"}, "Error:"),
    ("/axis-cgi/apidiscovery.cgi", "json", b"{not json", '"code": 4000'),
    ("/axis-cgi/basicdeviceinfo.cgi", "json", b'{"apiVersion": "1.1", "method": "reboot"}',
     '"code": 2004'),
    ("/axis-cgi/pwdgrp.cgi", "form", {"action": "remove", "user": "root"}, "Error:"),
    ("/axis-cgi/mjpg/video.cgi", "form", {"fps": "0"}, "Error:"),
    ("/axis-cgi/nothing.cgi", "form", {}, "Not Found"),
])
def test_what_it_cannot_do_gets_the_cameras_refusal(camera: tuple, path: str, kind: str,
                                                     payload: object, expect: str) -> None:
    _, client = camera
    if kind == "json":
        reply = client.post(path, content=payload,
                            headers={"Content-Type": "application/json"})
    else:
        reply = client.post(path, data=payload)
    assert expect in reply.text


def test_the_sim_owns_its_vapix_constants() -> None:
    """The simulated cameras must not take paths or shapes from our client: a wrong constant
    would then pass on both sides."""
    for path in sorted((ROOT / "services" / "sim").glob("*.py")):
        tree = ast.parse(path.read_text())
        imported = {node.module for node in ast.walk(tree)
                    if isinstance(node, ast.ImportFrom) and node.module}
        assert "services.ptz.vapix" not in imported and "services.ptz.camera" not in imported, \
            path.name
