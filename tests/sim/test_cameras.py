"""The simulated AXIS cameras over real HTTP: VAPIX answers, auth, motion, snapshots."""

from __future__ import annotations

import time
from collections.abc import Iterator
from dataclasses import replace

import cv2
import httpx
import numpy as np
import pytest
from pydantic import ValidationError

from common.camera import Intrinsics, Pose, project
from common.markers import detect
from common.ptz_lens import PtzLens
from services.sim import vapix
from services.sim.camera_server import CameraServer, SimCamera, answer
from services.sim.lab import Lab
from services.sim.ptz import PtzHead
from services.sim.scene import DAY, GroundView
from services.sim.settings import PtzCameraSettings

PTZ = "/axis-cgi/com/ptz.cgi"
IMAGE = "/axis-cgi/jpg/image.cgi"


class Clock:
    """The cameras' clock, moved on by the test: motion is judged at given times, never by
    waiting on the wall clock."""

    def __init__(self) -> None:
        self.now_s = 0.0

    def __call__(self) -> float:
        return self.now_s

    def advance(self, seconds: float) -> None:
        self.now_s += seconds


@pytest.fixture
def clock() -> Clock:
    return Clock()


@pytest.fixture
def servers(lab: Lab, clock: Clock) -> Iterator[dict[str, tuple[CameraServer, httpx.Client]]]:
    out = {}
    for i, cam in enumerate(lab.settings.cameras):
        # A still scene (the robot at its start), so a snapshot and a prediction agree.
        sim = SimCamera(cam.name, lab.heads[cam.name], lambda _t: lab.bright_points(0.0),
                        lab.ptz_glints, clock, np.random.default_rng(i), cam.user, cam.password,
                        ground=GroundView.of(lab.crater), robots=lambda _t: [lab.robot_pose(0.0)])
        server = CameraServer(sim, "127.0.0.1", cam.port).start()
        client = httpx.Client(base_url=f"http://127.0.0.1:{server.port}", timeout=3,
                              auth=httpx.DigestAuth(cam.user, cam.password))
        out[cam.name] = (server, client)
    yield out
    for server, client in out.values():
        client.close()
        server.close()


def _position(client: httpx.Client) -> dict[str, float]:
    reply = client.get(PTZ, params={"query": "position"})
    assert reply.status_code == 200
    pairs = dict(line.split("=", 1) for line in reply.text.split())
    return {k: float(pairs[k]) for k in ("pan", "tilt", "zoom")}


def test_requests_without_or_with_wrong_credentials_get_401(servers: dict) -> None:
    server, client = servers["ptz1"]
    base = f"http://127.0.0.1:{server.port}"
    bare = httpx.get(base + PTZ, params={"query": "position"})
    assert bare.status_code == 401
    assert bare.headers["WWW-Authenticate"].startswith('Digest realm="AXIS_')
    wrong = httpx.get(base + PTZ, params={"query": "position"},
                      auth=httpx.DigestAuth("root", "wrong"))
    assert wrong.status_code == 401
    assert client.get(PTZ, params={"query": "position"}).status_code == 200


def test_basic_auth_when_the_camera_is_set_to_it(lab: Lab) -> None:
    sim = SimCamera("cam", lab.heads["ptz1"], lambda _t: lab.bright_points(0.0), [], lambda: 0.0,
                    np.random.default_rng(0), "operator", "secret", auth="basic")
    server = CameraServer(sim, "127.0.0.1", 0).start()
    try:
        base = f"http://127.0.0.1:{server.port}{PTZ}?query=limits"
        assert httpx.get(base).headers["WWW-Authenticate"].startswith("Basic")
        assert httpx.get(base, auth=("operator", "secret")).status_code == 200
        assert httpx.get(base, auth=("operator", "nope")).status_code == 401
    finally:
        server.close()


def test_a_move_takes_time_after_the_command_latency(servers: dict, clock: Clock) -> None:
    _, client = servers["ptz1"]
    assert client.get(PTZ, params={"pan": "40", "tilt": "-10"}).status_code == 204
    clock.advance(0.1)
    assert _position(client)["pan"] == 0.0, "nothing happens before the command latency"
    clock.advance(0.15)
    partway = _position(client)["pan"]
    assert 0 < partway < 40, "pan moves at finite speed (100°/s)"
    clock.advance(0.5)
    assert _position(client) == {"pan": 40.0, "tilt": -10.0, "zoom": 1.0}


def test_limits_hold_and_are_reported(servers: dict, clock: Clock) -> None:
    _, client = servers["ptz2"]
    reply = client.get(PTZ, params={"query": "limits"})
    limits = dict(line.split("=") for line in reply.text.split())
    assert limits["MinPan"] == "-170" and limits["MaxPan"] == "170"
    assert limits["MinTilt"] == "-90" and limits["MaxZoom"] == "9999"
    client.get(PTZ, params={"pan": "400", "tilt": "-120", "zoom": "20000", "speed": "100"})
    clock.advance(5.0)
    assert _position(client) == {"pan": 170.0, "tilt": -90.0, "zoom": 9999.0}


@pytest.mark.parametrize(("params", "message"), [
    ({"pan": "abc"}, 'Error: pan: invalid value "abc"'),
    ({"pann": "1"}, 'Error: unknown argument "pann"'),
    ({"query": "everything"}, 'Error: query: unknown value "everything"'),
    ({"continuouspantiltmove": "200,0"}, "Error: continuouspantiltmove: invalid value"),
    ({"camera": "3", "pan": "1"}, 'Error: camera: invalid value "3"'),
    ({"move": "sideways"}, 'Error: move: invalid value "sideways"'),
])
def test_errors_come_as_http_200_with_an_error_body(servers: dict, params: dict,
                                                    message: str) -> None:
    _, client = servers["ptz1"]
    reply = client.get(PTZ, params=params)
    assert reply.status_code == 200 and reply.text.startswith(message)


def test_continuous_move_and_stop(servers: dict, clock: Clock) -> None:
    _, client = servers["ptz1"]
    assert client.post(PTZ, data={"continuouspantiltmove": "50,0"}).status_code == 204
    clock.advance(0.5)
    assert client.get(PTZ, params={"continuouspantiltmove": "0,0"}).status_code == 204
    clock.advance(0.3)
    stopped = _position(client)["pan"]
    clock.advance(0.3)
    assert stopped == _position(client)["pan"] and 5 < stopped < 40


def test_info_lists_the_ir_cut_filter(servers: dict) -> None:
    _, client = servers["ptz1"]
    assert "ircutfilter={ on | off | auto }" in client.get(PTZ, params={"info": "1"}).text


def _snapshot(client: httpx.Client, **params: str) -> np.ndarray:
    reply = client.get(IMAGE, params=params)
    assert reply.status_code == 200 and reply.headers["Content-Type"] == "image/jpeg"
    image = cv2.imdecode(np.frombuffer(reply.content, np.uint8), cv2.IMREAD_GRAYSCALE)
    assert image is not None, "not a JPEG"
    return image


def _bright_spots(image: np.ndarray, threshold: int = 128) -> list[tuple[float, float, float]]:
    """(u, v, area) of bright regions, intensity-weighted centroids."""
    count, labels = cv2.connectedComponents((image > threshold).astype(np.uint8))
    out = []
    for label in range(1, count):
        rows, cols = np.nonzero(labels == label)
        w = image[rows, cols].astype(float)
        out.append((float((cols * w).sum() / w.sum()), float((rows * w).sum() / w.sum()),
                    float(len(rows))))
    return out


def test_ir_lit_marker_is_visible_only_with_the_ir_cut_filter_off(servers: dict) -> None:
    _, client = servers["ptz1"]
    client.get(PTZ, params={"ircutfilter": "on"})
    day = _snapshot(client)
    assert day.max() < 203, "nothing in the day view reaches the detector's lowest threshold"
    assert detect(day).markers == ()
    client.get(PTZ, params={"ircutfilter": "off"})
    infrared = _snapshot(client)
    assert infrared.max() > 200
    assert np.median(infrared) < np.median(day) - 40, "the IR view is the dark one"


@pytest.mark.parametrize("camera", ["ptz1", "ptz2"])
def test_the_picture_shows_the_crater_and_the_robot(servers: dict, lab: Lab,
                                                    camera: str) -> None:
    server, client = servers[camera]
    client.get(PTZ, params={"ircutfilter": "auto"})
    image = _snapshot(client, compression="0").astype(float)
    low, high = np.percentile(image, [5, 95])
    assert high - low > 40, "shaded ground, not a flat field"
    head, now = lab.heads[camera], server.camera.clock()
    marker, _, ground = lab.robot_pose(0.0)
    below = marker - [0.0, 0.0, (marker[2] - ground) / 2]  # the middle of its chassis
    u, v = project(below[None, :], head.pose(now), head.intrinsics(now, 704, 576))[0]
    assert 0 < u < 704 and 0 < v < 576, "the robot is in this camera's view"
    chassis = image[int(v) - 1:int(v) + 2, int(u) - 1:int(u) + 2].mean()
    around = np.median(image[max(int(v) - 60, 0):int(v) + 60, max(int(u) - 60, 0):int(u) + 60])
    assert chassis < DAY.chassis + 15 and around - chassis > 40, (chassis, around)


@pytest.mark.parametrize("camera", ["ptz1", "ptz2"])
def test_marker_renders_where_the_camera_model_predicts(servers: dict, lab: Lab, clock: Clock,
                                                        camera: str) -> None:
    server, client = servers[camera]
    head = lab.heads[camera]
    # Point near the robot (eq. 4 on the mount frame), a little off so it is not centred.
    x, y, z = head.mount.to_camera(lab.bright_points(0.0)[:1])[0]
    pan = np.degrees(np.arctan2(y, x)) + 1.5
    tilt = -np.degrees(np.arctan2(z, np.hypot(x, y))) - 1.0
    client.get(PTZ, params={"ircutfilter": "off", "pan": f"{pan:.3f}", "tilt": f"{tilt:.3f}",
                            "zoom": "1500"})
    clock.advance(3.0)
    assert not head.state(server.camera.clock())[3], "camera has stopped moving"
    image = _snapshot(client, compression="0")
    assert image.shape == (576, 704)
    now = server.camera.clock()
    predicted = project(lab.bright_points(0.0), head.pose(now), head.intrinsics(now, 704, 576))
    visible = [(u, v) for u, v in predicted if 5 < u < 699 and 5 < v < 571]
    assert visible, "the scene must put at least one marker in view"
    spots = _bright_spots(image)
    for u, v in visible:
        nearest = min(spots, key=lambda s: np.hypot(s[0] - u, s[1] - v))
        assert np.hypot(nearest[0] - u, nearest[1] - v) < 1.0


def test_snapshot_resolutions(servers: dict) -> None:
    _, client = servers["ptz1"]
    assert _snapshot(client, resolution="352x288").shape == (288, 352)
    reply = client.get(IMAGE, params={"resolution": "1920x1080"})
    assert reply.text.startswith('Error: resolution: invalid value "1920x1080"')


def test_relative_moves_add_up_and_home_returns(servers: dict, clock: Clock) -> None:
    _, client = servers["ptz2"]
    for _ in range(2):
        assert client.get(PTZ, params={"rpan": "10", "rtilt": "-5"}).status_code == 204
        clock.advance(0.4)
    assert _position(client)["pan"] == 20.0 and _position(client)["tilt"] == -10.0
    client.get(PTZ, params={"move": "home"})
    clock.advance(0.5)
    assert _position(client)["pan"] == 0.0 and _position(client)["tilt"] == 0.0


def _grid_in_view(head_pose_: Pose, intr: Intrinsics, depth_mm: float) -> np.ndarray:
    """World points that a pinhole camera would see on a 7×5 grid reaching the picture's
    corners, at one depth."""
    u, v = np.meshgrid(np.linspace(40, intr.width_px - 40, 7),
                       np.linspace(40, intr.height_px - 40, 5))
    rays = np.column_stack([np.ones(u.size), (u.ravel() - intr.cy_px) / intr.fy_px,
                            (v.ravel() - intr.cz_px) / intr.fz_px])
    return head_pose_.to_world(rays * depth_mm)


@pytest.mark.parametrize("seed", range(3))
def test_a_sim_camera_draws_through_its_own_lens(seed: int) -> None:
    """A lens drawn at random (zoom curve and barrel distortion, as `[[sim.cameras]]` sets
    them): markers appear where OpenCV's model of that lens puts them, up to the corners —
    several pixels from where the straight-line pinhole would."""
    rng = np.random.default_rng(seed)
    table = [(1.0, 3.8), (3000.0, rng.uniform(4.6, 5.4)), (7000.0, rng.uniform(9.0, 12.0)),
             (9999.0, rng.uniform(40.0, 48.0))]
    wide = (rng.uniform(-0.35, -0.2), rng.uniform(0.05, 0.15), rng.uniform(-2e-3, 2e-3),
            rng.uniform(-2e-3, 2e-3), 0.0)
    settings = PtzCameraSettings(name="ptz1", port=0, x_mm=0, y_mm=0, z_mm=2000, rx_deg=180,
                                 ry_deg=30, rz_deg=0, zoom_focal_mm=table, distortion=wide)
    head = PtzHead(Pose.of(settings), lens=settings.lens())
    head.ir_cut_filter = "off"
    zoom = int(rng.integers(1, 800))
    head.absolute(0.0, 0.0, 0.0, zoom)
    truth = head.intrinsics(10.0, 704, 576)
    assert truth.focal_px == pytest.approx(settings.lens().focal_px(zoom))
    assert truth.fy_px == pytest.approx(settings.lens().focal_px(zoom))
    points = _grid_in_view(head.pose(10.0), truth.pinhole(), 3000.0)
    camera = SimCamera("ptz1", head, lambda _t: points, [], lambda: 10.0,
                       np.random.default_rng(seed))
    spots = _bright_spots(camera.snapshot(704, 576))
    expected = project(points, head.pose(10.0), truth)
    straight = project(points, head.pose(10.0), PtzLens().intrinsics(zoom))
    inside = [(u, v) for u, v in expected if 4 < u < 700 and 4 < v < 572]
    assert len(inside) >= 20
    worst_pinhole = 0.0
    for (u, v), (us, vs) in zip(expected, straight, strict=True):
        if not (4 < u < 700 and 4 < v < 572):
            continue
        nearest = min(spots, key=lambda s: np.hypot(s[0] - u, s[1] - v))
        assert np.hypot(nearest[0] - u, nearest[1] - v) < 0.5
        worst_pinhole = max(worst_pinhole, float(np.hypot(us - u, vs - v)))
    assert worst_pinhole > 5.0


def test_a_snapshot_is_of_when_its_request_reached_the_camera() -> None:
    """A request handled 0.2 s after it arrived (the sim's thread busy with other work)
    pictures the wand where it was when the request came, as a camera with its own sensor
    would: not where it was 0.2 s later (1 m/s: 200 mm, tens of pixels)."""
    head = PtzHead(Pose(0, 0, 2000, 180, 30, 0))
    head.ir_cut_filter = "off"
    head.absolute(0.0, 0.0, 0.0, 1)
    start = _grid_in_view(head.pose(10.0), head.intrinsics(10.0, 704, 576), 3000.0)[17]

    def wand(t: float) -> np.ndarray:  # across the picture at 1 m/s
        return (start + np.array([0.0, 1000.0, 0.0]) * (t - 10.0))[None, :]

    camera = SimCamera("ptz1", head, wand, [], lambda: 10.0, np.random.default_rng(5))
    reply = answer(camera, vapix.IMAGE_PATH, {"resolution": "704x576"}, b"", None,
                   time.time() - 0.2)
    image = cv2.imdecode(np.frombuffer(reply.body, np.uint8), cv2.IMREAD_GRAYSCALE)
    assert image is not None, reply
    (u, v, _), = _bright_spots(image)
    intr = head.intrinsics(10.0, 704, 576)
    arrived = project(wand(9.8), head.pose(10.0), intr)[0]
    handled = project(wand(10.0), head.pose(10.0), intr)[0]
    assert np.hypot(u - arrived[0], v - arrived[1]) < 1.0
    assert np.hypot(*(arrived - handled)) > 30.0


def test_a_lens_table_that_is_no_curve_stops_the_lab_file_naming_the_field() -> None:
    with pytest.raises(ValidationError, match="zoom_focal_mm"):
        PtzCameraSettings(name="ptz1", port=0, x_mm=0, y_mm=0, z_mm=0, rx_deg=0, ry_deg=0,
                          rz_deg=0, zoom_focal_mm=[(1, 3.8), (5000, 3.0), (9999, 46.0)])


def test_a_16_9_camera_says_its_picture_and_draws_through_its_principal_point() -> None:
    """A current camera (1920 × 1080, its own chip, the principal point off the centre) over
    real HTTP: our VAPIX client reads its picture size from ``param.cgi``, a snapshot without a
    resolution is its full picture, its half is offered and the AXIS 215's size refused; the
    markers land where its true lens — principal point included — puts them."""
    from services.ptz.camera import AxisPtzCamera

    settings = PtzCameraSettings(name="ptz1", port=0, x_mm=0, y_mm=0, z_mm=2000, rx_deg=180,
                                 ry_deg=30, rz_deg=0, picture_px=(1920, 1080),
                                 chip_mm=(5.6, 3.15), principal_offset_px=(21.0, -13.0))
    head = settings.head()
    head.ir_cut_filter = "off"
    truth = head.intrinsics(10.0)
    assert (truth.cy_px, truth.cz_px) == (981.0, 527.0) and truth.fz_px == truth.fy_px
    points = _grid_in_view(head.pose(10.0), truth.pinhole(), 3000.0)
    sim = SimCamera("ptz1", head, lambda _t: points, [], lambda: 10.0, np.random.default_rng(4),
                    resolutions=settings.resolutions())
    server = CameraServer(sim, "127.0.0.1", 0).start()
    try:
        # the first 1920 × 1080 picture draws the sensor's noise fields (about a second alone;
        # a CI run beside the other worker passed 3 s): a bound on the wait, not a figure
        with httpx.Client(base_url=f"http://127.0.0.1:{server.port}", timeout=30,
                          auth=httpx.DigestAuth("root", "pass")) as client:
            assert AxisPtzCamera(client, "ptz1").picture() == (1920, 1080)
            image = AxisPtzCamera(client, "ptz1").snapshot()
            assert image.shape == (1080, 1920)
            assert _snapshot(client, resolution="960x540").shape == (540, 960)
            assert "Error" in client.get(IMAGE, params={"resolution": "704x576"}).text
    finally:
        server.close()
    expected = project(points, head.pose(10.0), truth)
    centred = project(points, head.pose(10.0), replace(truth, principal_px=None))
    spots = _bright_spots(image)
    inside = [(u, v) for u, v in expected if 6 < u < 1914 and 6 < v < 1074]
    assert len(inside) >= 20
    for u, v in inside:
        nearest = min(spots, key=lambda s: np.hypot(s[0] - u, s[1] - v))
        assert np.hypot(nearest[0] - u, nearest[1] - v) < 0.5
    assert np.allclose(expected - centred, [21.0, -13.0])


def test_a_picture_or_chip_that_cannot_be_stops_the_lab_file_naming_the_field() -> None:
    pose = {"x_mm": 0, "y_mm": 0, "z_mm": 0, "rx_deg": 0, "ry_deg": 0, "rz_deg": 0}
    with pytest.raises(ValidationError, match="picture_px"):
        PtzCameraSettings(name="ptz1", port=0, **pose, picture_px=(1919, 1080))
    with pytest.raises(ValidationError, match="chip_mm"):
        PtzCameraSettings(name="ptz1", port=0, **pose, chip_mm=(0.0, 3.0))
    assert PtzCameraSettings(name="ptz1", port=0, **pose, picture_px=(1920, 1080)
                             ).resolutions() == {"1920x1080": (1920, 1080),
                                                 "960x540": (960, 540), "480x270": (480, 270)}
