"""The AXIS driver against the sim's camera server over real HTTP (Digest and Basic)."""

from __future__ import annotations

import time
from collections.abc import Iterator

import numpy as np
import pytest

from common.camera import Pose, PtzLimits
from common.lab_views import CameraAuth
from services.ptz import vapix
from services.ptz.camera import (
    AxisPtzCamera,
    PtzRejected,
    PtzUnauthorized,
    PtzUnreachable,
    http_client,
)
from services.sim.camera_server import CameraServer, SimCamera
from services.sim.ptz import PtzHead
from tests.conftest import free_port, wait_for


@pytest.fixture
def server() -> Iterator[CameraServer]:
    t0 = time.monotonic()
    head = PtzHead(Pose(0, 0, 2000, 180, 30, 0))
    sim = SimCamera("ptz1", head, lambda _t: np.array([[3000.0, 0.0, 0.0]]), [],
                    lambda: time.monotonic() - t0, np.random.default_rng(0), "root", "secret")
    server = CameraServer(sim, "127.0.0.1", 0).start()
    yield server
    server.close()


def _camera(server: CameraServer, password: str = "secret", auth: CameraAuth = "digest"
            ) -> AxisPtzCamera:
    return AxisPtzCamera(http_client(f"http://127.0.0.1:{server.port}", "root", password, auth),
                         "ptz1")


def test_position_limits_and_a_move(server: CameraServer) -> None:
    camera = _camera(server)
    assert camera.limits() == PtzLimits(-170, 170, -90, 90, 1, 9999)
    assert camera.position() == vapix.Position(0.0, 0.0, 1, "auto")
    camera.move_to(12.5, -7.25, zoom=400, speed=100)
    wait_for(lambda: camera.position() == vapix.Position(12.5, -7.25, 400, "auto"), timeout=3,
             period=0.05, why=lambda: str(camera.position()))


def test_ir_cut_filter_and_snapshot(server: CameraServer) -> None:
    camera = _camera(server)
    camera.set_ir_cut_filter("off")
    assert camera.position().ir_cut_filter == "off"
    image = camera.snapshot()
    assert image.shape == (576, 704) and image.dtype == np.uint8
    with pytest.raises(ValueError, match="on, off or auto"):
        camera.set_ir_cut_filter("maybe")


def test_refusals_become_errors(server: CameraServer) -> None:
    camera = _camera(server)
    with pytest.raises(PtzRejected, match="invalid value"):
        camera._request(vapix.PTZ_PATH, {"pan": "abc"})
    with pytest.raises(PtzUnauthorized, match="401"):
        _camera(server, password="wrong").position()
    with pytest.raises(PtzUnauthorized):
        _camera(server, auth="basic").position()  # this camera only offers Digest


def test_unreachable_camera_is_reported_quickly() -> None:
    camera = AxisPtzCamera(http_client(f"http://127.0.0.1:{free_port()}", "root", "x",
                                       timeout_s=0.5), "gone")
    start = time.monotonic()
    with pytest.raises(PtzUnreachable, match="gone"):
        camera.position()
    assert time.monotonic() - start < 1.0


def test_move_params_are_clamped_to_vapix_ranges() -> None:
    assert vapix.move_params(400.0, -200.0, 20000, 0) == {
        "pan": "180.0000", "tilt": "-180.0000", "zoom": "9999", "speed": "1"}
    assert vapix.move_params(tilt_deg=3.0) == {"tilt": "3.0000"}


@pytest.mark.parametrize("body", ["", "pan=abc\ntilt=1", "<html>hello</html>"])
def test_garbage_replies_are_clear_errors(body: str) -> None:
    with pytest.raises(vapix.VapixReplyError):
        vapix.parse_position(body)
    with pytest.raises(vapix.VapixReplyError):
        vapix.parse_limits(body)


def test_error_body_detection() -> None:
    assert vapix.error_message('Error: pan: invalid value "x"\r\n') == 'pan: invalid value "x"'
    assert vapix.error_message("pan=1\r\n") is None
