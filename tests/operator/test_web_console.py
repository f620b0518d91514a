"""The page as a console, over HTTP against real buses: calibrations (for an operator's
review), a hand on a PTZ camera, recordings with their reports — operators only, each as a
message on the bus or a process on the page's host."""

from __future__ import annotations

import json
import queue
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TypeVar

import pytest

from common import keys
from common import messages as m
from common.bus import Bus
from common.settings import bus_environment
from services.web.app import build_app
from services.web.console import Console
from services.web.crater_image import CraterImage
from services.web.gate import Gate
from services.web.recordings import RecordingDesk
from services.web.server import WebServer
from services.web.users import Users
from tests.conftest import client_settings, wait_for
from tests.uplab import OPERATOR, VIEWER, write_users
from tests.webpage import PageClient

M = TypeVar("M", bound=m.Message)


@pytest.fixture
def console_page(tmp_path: Path, make_bus: Callable[..., Bus], router_endpoint: str
                 ) -> Iterator[tuple[PageClient, Bus, RecordingDesk]]:
    users = Users.load(write_users(tmp_path / "users.json"))
    desk = RecordingDesk(tmp_path / "recordings",
                         bus_environment(client_settings(router_endpoint)))
    app = build_app(Gate(users, 3600, tls=False), dict, lambda c: None, lambda c: None,
                    CraterImage(None),
                    push_period_s=1, max_streams=2, console=Console(make_bus(), desk, 40))
    web = WebServer(app, "127.0.0.1", 0).start()
    try:
        yield PageClient(f"http://127.0.0.1:{web.port}"), make_bus(), desk
    finally:
        web.close()


def _subscribed(bus: Bus, got: queue.Queue[M], topic: keys.Topic[M], probe: M,
                camera: str) -> None:
    """Until a probe sent on the key comes back: the subscription has reached the router
    (probes may still be on their way after: ``_next`` passes over them)."""
    wait_for(lambda: bus.publish(topic, probe, camera=camera) or not got.empty(), timeout=10,
             period=0.1)


def _next(got: queue.Queue[M], probe: M) -> M:
    while True:
        msg = got.get(timeout=5)
        if msg.model_dump(exclude={"measured_s", "sent_s"}) != probe.model_dump(
                exclude={"measured_s", "sent_s"}):
            return msg


def _empty_but_probes(got: queue.Queue, probe: m.Message) -> bool:
    while not got.empty():
        if _next(got, probe) is not None:
            return False
    return True


def _post(page: PageClient, path: str, user: tuple[str, str], body: object = None
          ) -> tuple[int, dict]:
    cookie, csrf, _ = page.sign_in(user)
    status, _, reply = page.request("POST", path, cookie=cookie, body=body,
                                    headers={"X-CSRF-Token": csrf})
    return status, json.loads(reply or b"{}")


def test_a_calibration_from_the_page_is_held_for_review(console_page: tuple) -> None:
    page, bus, _ = console_page
    got: queue.Queue[m.CollectRequest] = queue.Queue()
    bus.subscribe(keys.CALIB_COLLECT, got.put, latest=False, camera="ptz1")
    probe = m.CollectRequest(measured_s=time.time(), camera="ptz1", action="cancel")
    _subscribed(bus, got, keys.CALIB_COLLECT, probe, camera="ptz1")
    for action in ("start", "accept", "discard", "cancel"):
        status, answer = _post(page, f"/calib/ptz1/{action}", OPERATOR)
        assert status == 200 and answer["accepted"], answer
        request = _next(got, probe)
        assert (request.camera, request.action, request.review, request.count) == (
            "ptz1", action, True, 40)
    assert _post(page, "/calib/ptz1/start", VIEWER)[0] == 403
    assert _post(page, "/calib/ptz1/explode", OPERATOR)[0] == 404
    assert page.request("POST", "/calib/ptz1/start")[0] == 401
    assert _empty_but_probes(got, probe), "nothing from a viewer, a stranger or a bad action"


def test_an_operators_hand_on_a_camera(console_page: tuple) -> None:
    page, bus, _ = console_page
    got: queue.Queue[m.PtzHand] = queue.Queue()
    bus.subscribe(keys.PTZ_HAND, got.put, latest=False, camera="ptz2")
    probe = m.PtzHand(measured_s=time.time(), camera="ptz2", action="follow", operator="probe")
    _subscribed(bus, got, keys.PTZ_HAND, probe, camera="ptz2")
    for action, body in (("hold", None), ("move", {"pan_deg": -20.0, "tilt_deg": -35.0,
                                                   "zoom": 3000}),
                         ("nudge", {"pan_deg": -5.0, "tilt_deg": 0.0, "zoom": -1000}),
                         ("preset", {"preset": "Home"}), ("follow", None)):
        status, answer = _post(page, f"/ptz/ptz2/{action}", OPERATOR, body)
        assert status == 200 and answer["accepted"], answer
        hand = _next(got, probe)
        assert hand.action == action and hand.operator == "olga (web 127.0.0.1)"
    assert (hand.pan_deg, hand.preset) == (None, "")
    status, answer = _post(page, "/ptz/ptz2/move", OPERATOR, {"pan_deg": 400.0})
    assert status == 400 and "pan_deg" in answer["detail"], "out of range: refused, said why"
    status, answer = _post(page, "/ptz/ptz2/move", OPERATOR, {"tilt_deg": 120.0})
    assert status == 400 and "within ±90" in answer["detail"]
    assert _post(page, "/ptz/ptz2/hold", VIEWER)[0] == 403
    assert _empty_but_probes(got, probe)


def test_a_recording_from_the_page_and_its_report(console_page: tuple) -> None:
    page, bus, desk = console_page
    status, answer = _post(page, "/record/start", OPERATOR, {"seconds": 3})
    assert status == 200 and answer["accepted"], answer
    name = answer["name"]
    assert _post(page, "/record/start", OPERATOR)[0] == 409, "one at a time"
    assert _post(page, "/record/stop", VIEWER)[0] == 403

    def listed() -> dict | None:
        view = json.loads(page.request("GET", "/recordings.json", auth=VIEWER)[2])
        return next((r for r in view["past"] if r["name"] == name and r["report"]), None)

    entry = wait_for(listed, timeout=120, period=0.5)
    status, headers, body = page.request("GET", f"/{entry['report']}", auth=VIEWER)
    assert status == 200 and b"<html" in body.lower()
    assert page.request("GET", f"/recordings/{name}/..%2Fusers.json", auth=VIEWER)[0] == 404
    assert page.request("GET", f"/{entry['report']}")[0] == 401
    status, answer = _post(page, "/record/stop", OPERATOR)
    assert status == 409 and "no recording runs" in answer["detail"]
