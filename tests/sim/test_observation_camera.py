"""The crane's observation camera in the sim: a colour top view that moves with the crane and
shows the robot where the camera's geometry puts it, served over VAPIX with Digest."""

from __future__ import annotations

import time
from collections.abc import Iterator

import cv2
import httpx
import numpy as np
import pytest

from common.crane_frame import CraneFrame
from common.mjpeg import MjpegParts, boundary_of
from services.sim.camera_server import CameraServer
from services.sim.observation import ObservationCamera, ObservationView
from services.sim.scene import GroundView
from services.sim.world import CraterMap

ALIGNED = CraneFrame()
VIEW = ObservationView(focal_mm=6.0, chip_mm=(4.8, 3.6), offset_mm=(150.0, 0.0),
                       height_mm=3450.0)


def _camera(crater: CraterMap, crane_xy: list[float], marker: tuple[float, float, float],
            frame: CraneFrame = ALIGNED) -> ObservationCamera:
    ground = float(crater.height_at(marker[0], marker[1]))
    return ObservationCamera("observation", VIEW, GroundView.of(crater), frame,
                             lambda _t: np.array(crane_xy, float),
                             lambda _t: (np.array(marker), 0.3, ground, 200.0),
                             time.monotonic, np.random.default_rng(0))


def _white_spot(image: np.ndarray) -> np.ndarray:
    """Where the robot's marker (the only white in the picture) is, pixels (u, v)."""
    rows, cols = np.nonzero(np.all(image > 225, axis=2))
    assert len(rows), "no marker in the picture"
    return np.array([cols.mean(), rows.mean()])


def test_the_robot_below_the_lens_is_at_the_picture_s_centre_in_colour(crater: CraterMap
                                                                       ) -> None:
    marker = (400.0, -300.0, float(crater.height_at(400.0, -300.0)) + 300.0)
    image = _camera(crater, [marker[0] - 150.0, marker[1]], marker).snapshot(640, 480)
    assert image.shape == (480, 640, 3)
    assert np.abs(_white_spot(image) - [319.5, 239.5]).max() < 2.0
    b, g, r = (image[..., i].astype(float).mean() for i in range(3))
    assert r > g > b, "the regolith is a warm grey, not grey"
    body = np.all(np.abs(image.astype(int) - (92, 70, 56)) < 25, axis=2)
    assert body[200:280, 270:370].mean() > 0.2, "the robot's body around its marker"


def test_the_picture_moves_with_the_crane_and_turns_with_its_axes(crater: CraterMap) -> None:
    marker = (0.0, 0.0, float(crater.height_at(0.0, 0.0)) + 300.0)
    f_px = 6.0 / (4.8 / 640)
    depth = VIEW.height_mm - marker[2]
    # the crane 400 mm further along world x: the robot 400 mm to the left (u falls)
    moved = _white_spot(_camera(crater, [-150.0 + 400.0, 0.0], marker).snapshot(640, 480))
    assert np.abs(moved - [319.5 - 400.0 * f_px / depth, 239.5]).max() < 2.0
    # a crane turned 90° counting from a corner: its x axis is the world's y; the lens is
    # 150 mm along that (world +y) from its reported point, and the picture's u grows along it
    turned = CraneFrame(origin_mm=(1000.0, -500.0), yaw_deg=90.0)
    crane_xy = [0.0, -150.0 + 300.0]  # the lens 300 mm north of the robot
    spot = _white_spot(_camera(crater, crane_xy, marker, turned).snapshot(640, 480))
    assert np.abs(spot - [319.5 - 300.0 * f_px / depth, 239.5]).max() < 2.0


@pytest.fixture
def served(crater: CraterMap) -> Iterator[httpx.Client]:
    marker = (0.0, 0.0, float(crater.height_at(0.0, 0.0)) + 300.0)
    server = CameraServer(_camera(crater, [-150.0, 0.0], marker), "127.0.0.1", 0).start()
    client = httpx.Client(base_url=f"http://127.0.0.1:{server.port}", timeout=5,
                          auth=httpx.DigestAuth("root", "pass"))
    yield client
    client.close()
    server.close()


def test_it_serves_colour_pictures_and_video_and_nothing_of_a_ptz_camera(
        served: httpx.Client) -> None:
    reply = served.get("/axis-cgi/jpg/image.cgi")
    assert reply.status_code == 200 and reply.headers["content-type"] == "image/jpeg"
    image = cv2.imdecode(np.frombuffer(reply.content, np.uint8), cv2.IMREAD_UNCHANGED)
    assert image is not None and image.shape == (480, 640, 3)
    small = served.get("/axis-cgi/jpg/image.cgi", params={"resolution": "320x240"})
    picture = cv2.imdecode(np.frombuffer(small.content, np.uint8), 1)
    assert picture is not None and picture.shape == (240, 320, 3)
    bad = served.get("/axis-cgi/jpg/image.cgi", params={"resolution": "704x576"})
    assert "resolution" in bad.text
    assert served.get("/axis-cgi/com/ptz.cgi", params={"pan": "10"}).status_code == 404
    assert httpx.get(f"{served.base_url}/axis-cgi/jpg/image.cgi").status_code == 401
    with served.stream("GET", "/axis-cgi/mjpg/video.cgi",
                       params={"fps": "10", "nbrofframes": "3"}) as stream:
        parts = MjpegParts(boundary_of(stream.headers["content-type"]))
        jpegs = [jpeg for chunk in stream.iter_raw() for jpeg in parts.feed(chunk)]
    assert len(jpegs) == 3
