"""Calibration mode's requests: held inside the camera's limits (853 moves with |pan| 170–180°
against a ±170° limit before), and a burst of them does not queue up moves."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import httpx
import numpy as np
import pytest

from common import keys
from common import messages as m
from common.camera import PtzLimits
from services.ptz.calibration import CalibrationHold
from services.ptz.camera import AxisPtzCamera, PtzUnreachable, http_client
from services.sim.camera_server import CameraServer, SimCamera
from services.sim.lab import Lab
from tests.conftest import wait_for
from tests.ptz.test_service import _camera_server


class RecordingCamera:
    name = "ptz1"

    def __init__(self) -> None:
        self.moves: list[tuple | str] = []
        self.ir_cut: list[str] = []

    def move_to(self, pan: float | None, tilt: float | None, zoom: float | None,
                *_args: object, **_kwargs: object) -> None:
        self.moves.append((pan, tilt, zoom))

    def set_ir_cut_filter(self, mode: str) -> None:
        self.ir_cut.append(mode)

    def home(self) -> None:
        self.moves.append("home")


def _request(pan: float | None, tilt: float | None, zoom: int | None = None,
             active: bool = True) -> m.CalibrationMode:
    return m.CalibrationMode(measured_s=time.time(), camera="ptz1", active=active,
                             pan_deg=pan, tilt_deg=tilt, zoom=zoom, lease_s=1.0)


@pytest.mark.parametrize(("asked", "held"), [
    ((175.0, 10.0, 5), (170.0, 10.0, 5)),
    ((-180.0, -90.0, 20000 - 1), (-170.0, -80.0, 9999)),
    ((None, 95.0 - 10, None), ("home", (None, 80.0, None))),
    ((12.0, 3.0, 1), (12.0, 3.0, 1)),
])
def test_a_request_outside_the_cameras_limits_is_held_at_them(asked: tuple, held: tuple) -> None:
    camera = RecordingCamera()
    mode = CalibrationHold(camera, lambda _d: None, lambda _f: None)  # type: ignore[arg-type]
    limits = PtzLimits(min_tilt=-80.0, max_tilt=80.0)
    mode.on_request(_request(*asked), 100.0, limits)
    if held[0] == "home":  # what the request leaves open comes from home
        assert camera.moves == list(held)
        held = held[-1]
    else:
        assert camera.moves == [held]
    assert mode.request is not None
    assert (mode.request.pan_deg, mode.request.tilt_deg, mode.request.zoom) == held


def test_a_burst_of_requests_is_coalesced_not_queued(service: dict) -> None:
    """200 requests that alternate between ending and starting the mode (each start moves
    the camera): the service takes the newest, and the camera stops moving at once after."""
    server = _camera_server(service["port"])
    service["servers"].append(server)
    assert isinstance(server.camera, SimCamera)
    moves: list[float] = []  # when the camera got an absolute move over VAPIX
    absolute = server.camera.head.absolute

    def recorded(*args: Any, **kwargs: Any) -> None:
        moves.append(time.monotonic())
        absolute(*args, **kwargs)

    server.camera.head.absolute = recorded  # type: ignore[method-assign]
    service["thread"].start()
    world, states = service["world"], service["states"]
    wait_for(lambda: states)
    for k in range(200):
        world.publish(keys.PTZ_CALIBRATION, _request(-4.0 + (k % 7), 3.0, 1,
                                                     active=k % 2 == 1), camera="ptz1")
    sent = time.monotonic()
    time.sleep(1.5)  # the subject: what the camera does in the 1.5 s after a flood
    assert len(moves) < 50, len(moves)
    late = [t - sent for t in moves if t > sent + 0.5]
    assert not late, f"the camera still moved {max(late):.1f} s after the last request"



def _sim_camera(lab: Lab) -> tuple:
    """The lab's first camera served over VAPIX on loopback: (its settings, server, URL)."""
    cam = lab.settings.cameras[0]
    t0 = time.monotonic()
    sim = SimCamera(cam.name, lab.heads[cam.name], lambda _t: lab.bright_points(0.0), [],
                    lambda: time.monotonic() - t0, np.random.default_rng(0), cam.user,
                    cam.password)
    server = CameraServer(sim, "127.0.0.1", 0).start()
    return cam, server, f"http://127.0.0.1:{server.port}"


class HomeTimesOutOnce(AxisPtzCamera):
    """A camera whose first ``move=home`` gets no answer in time (a loaded network)."""

    failed = False

    def home(self) -> None:
        if not self.failed:
            self.failed = True
            raise PtzUnreachable(f"{self.name}: ReadTimeout")
        super().home()


def test_a_hold_command_lost_to_a_timeout_is_sent_again(lab: Lab) -> None:
    """The camera did not answer the command that takes it to its hold: it is sent again,
    so the passpoints come from the pan and tilt asked for, not from wherever it stood (a
    clean-clone CI collected at pan 0 for a collection held at pan 6)."""
    cam, server, url = _sim_camera(lab)
    detections: list[m.MarkerDetections] = []
    mode = CalibrationHold(HomeTimesOutOnce(http_client(url, cam.user, cam.password), cam.name),
                           detections.append, lambda _f: None)
    try:
        with pytest.raises(PtzUnreachable):
            mode.on_request(_request(6.0, -4.0), time.time(), PtzLimits())
        def cycled() -> list[m.MarkerDetections]:
            mode.cycle()
            return detections

        wait_for(cycled, timeout=5, period=0.1,  # its loop's pace
                 why=lambda: "no detections once it stands at its hold")
        assert mode.hold == (6.0, -4.0, 1)
        assert mode._last_position == mode.hold
    finally:
        server.close()


def test_the_hold_is_home_and_a_camera_moved_away_is_sent_back(lab: Lab) -> None:
    """Left looking elsewhere before calibration, and moved by another client during it, the
    camera is held at its home position: no passpoint comes from a foreign view."""
    cam, server, url = _sim_camera(lab)
    other = httpx.Client(base_url=url, auth=httpx.DigestAuth(cam.user, cam.password), timeout=3)
    detections: list[m.MarkerDetections] = []
    mode = CalibrationHold(AxisPtzCamera(http_client(url, cam.user, cam.password), cam.name),
                           detections.append, lambda _f: None)
    try:
        other.get("/axis-cgi/com/ptz.cgi", params={"pan": "60", "tilt": "20"})
        head = server.camera.head  # someone left it looking elsewhere
        wait_for(lambda: head.state(server.camera.clock())[:2] == (60.0, 20.0), timeout=5)
        mode.on_request(_request(None, None), time.time(), PtzLimits())

        def cycles_until(done: Callable[[], bool], timeout: float = 5.0) -> list[bool]:
            """Cycles until ``done()``: whether each published detections while the camera
            was off its hold."""
            wrong: list[bool] = []

            def cycle_unless_done() -> bool:
                if done():
                    return True
                before = len(detections)
                mode.cycle()
                assert mode._last_position is not None
                off = mode.hold is None or not mode._at_hold(*mode._last_position)
                wrong.append(off and len(detections) > before)
                return False

            wait_for(cycle_unless_done, timeout=timeout, period=0.1,  # the loop's pace
                     why=lambda: f"not done: {wrong}")
            return wrong

        def collecting_at_hold(since: int) -> bool:
            return (mode._last_position is not None and mode.hold is not None
                    and mode._at_hold(*mode._last_position) and len(detections) > since + 2)

        assert not any(cycles_until(lambda: collecting_at_hold(0)))
        assert mode.hold == (0.0, 0.0, 1), "held at home, not where it was left"
        held = len(detections)
        other.get("/axis-cgi/com/ptz.cgi", params={"pan": "40"})
        assert not any(cycles_until(lambda: mode.rehold_count >= 1
                                    and collecting_at_hold(held)))
    finally:
        other.close()
        server.close()
