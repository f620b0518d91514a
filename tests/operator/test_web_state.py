"""The page's state (pure) and its HTTP side without a bus."""

from __future__ import annotations

import json
import urllib.error
import urllib.request
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from common import messages as m
from common.heightmap import HeightMap
from services.ptz.aim import aim_at
from services.web.app import build_app
from services.web.crater_image import CraterImage
from services.web.gate import Gate
from services.web.server import WebServer
from services.web.state import LiveState, looking_at
from tests.calib.test_demo_calibration import MOUNTS


def _pose(camera: str = "ptz1") -> m.CameraPose:
    mount = MOUNTS[camera]
    return m.CameraPose(measured_s=1.0, camera=camera, **mount.fields(), focal_px=743.1,
                        mean_error_px=1.2, passpoints=90)


def _robot(t: float, x: float) -> m.RobotPosition:
    return m.RobotPosition(measured_s=t, label="robot", x_mm=x, y_mm=0.0, z_mm=0.0,
                           vx_mm_s=100.0, vy_mm_s=0.0, vz_mm_s=0.0)


@pytest.mark.parametrize("camera", ["ptz1", "ptz2"])
def test_a_camera_aimed_at_a_ground_point_looks_at_it(camera: str) -> None:
    target = np.array([500.0, -200.0, 0.0])
    pan, tilt = aim_at(target, MOUNTS[camera])
    assert looking_at(_pose(camera), pan, tilt) == pytest.approx([500.0, -200.0], abs=1.0)


def test_the_track_is_thinned_and_kept_for_track_s() -> None:
    state = LiveState(track_s=2.0)
    for i in range(400):  # 100 Hz for 4 s
        state.on_message(_robot(100.0 + i * 0.01, float(i)))
    view = state.view(104.0)
    assert 17 <= len(view["track"]) <= 21, "about 10 Hz over the last 2 s"
    assert view["track"][-1][0] >= 390.0
    assert view["robot"]["x_mm"] == 399.0 and view["robot"]["speed_mm_s"] == 100.0


def test_services_alive_gone_and_degraded() -> None:
    state = LiveState()
    state.on_alive("gantry", "main", True)
    state.on_alive("tracker", "main", True)
    state.on_message(m.ServiceHealth(measured_s=9.0, service="gantry", instance="main",
                                     host="h", pid=1, started_s=0.0, status="degraded",
                                     detail="crane unreachable", keys={}))
    state.on_alive("tracker", "main", False)
    rows = {(r["service"], r["alive"], r["status"]) for r in state.view(10.0)["services"]}
    assert rows == {("gantry", True, "degraded"), ("tracker", False, "")}


def test_cameras_show_pose_direction_and_preview_but_not_the_jpeg_in_the_json() -> None:
    state = LiveState()
    state.on_message(_pose())
    older = _pose().model_copy(update={"measured_s": 0.5, "x_mm": 0.0})
    state.on_message(older)
    state.on_message(m.PtzState(measured_s=2.0, camera="ptz1", status="tracking", pan_deg=-10,
                                tilt_deg=-8, zoom=1, focal_px=743.1, aim_error_deg=0.3))
    state.on_message(m.PtzPreview(measured_s=2.0, camera="ptz1", seq=7, width_px=704,
                                  height_px=576, jpeg=b"\xff\xd8jpeg", pan_deg=-10, tilt_deg=-8,
                                  markers=[], robot_px=[350.0, 290.0]))
    camera = state.view(3.0)["cameras"]["ptz1"]
    assert camera["position"][0] == MOUNTS["ptz1"].x_mm, "an older pose does not replace"
    assert camera["looking_at"] is not None and camera["preview"]["seq"] == "preview-7"
    assert "jpeg" not in json.dumps(state.view(3.0))
    assert state.preview_jpeg("ptz1") == b"\xff\xd8jpeg" and state.preview_jpeg("ptz9") is None


def test_in_calibration_mode_the_snapshot_with_its_markers_is_the_picture() -> None:
    state = LiveState()
    state.on_message(m.PtzPreview(measured_s=1.0, camera="ptz1", seq=3, width_px=704,
                                  height_px=576, jpeg=b"preview", pan_deg=0, tilt_deg=0,
                                  markers=[]))
    shot = m.CameraFrame(measured_s=2.0, camera="ptz1", seq=41, width_px=704, height_px=576,
                         encoding="jpeg", data=b"snapshot")
    state.on_message(shot)
    marker = m.DetectedMarker(u_px=100.0, v_px=200.0, radius_long_px=4.0, radius_short_px=3.9,
                              angle_deg=0.0, roundness=1.03, area_px=50)
    state.on_message(m.MarkerDetections(measured_s=1.9, camera="ptz1", status="ok",
                                        threshold=230, width_px=704, height_px=576,
                                        markers=[marker]))  # another snapshot's: not drawn
    shown = state.view(3.0)["cameras"]["ptz1"]["preview"]
    assert shown["kind"] == "calibration snapshot" and shown["seq"] == "snapshot-41"
    assert shown["markers"] == [] and state.preview_jpeg("ptz1") == b"snapshot"
    state.on_message(m.MarkerDetections(measured_s=2.0, camera="ptz1", status="ok",
                                        threshold=230, width_px=704, height_px=576,
                                        markers=[marker]))
    assert state.view(3.0)["cameras"]["ptz1"]["preview"]["markers"] == [[100.0, 200.0, 4.0]]
    state.on_message(m.PtzPreview(measured_s=5.0, camera="ptz1", seq=4, width_px=704,
                                  height_px=576, jpeg=b"later", pan_deg=0, tilt_deg=0,
                                  markers=[]))  # following again: the preview
    assert state.view(6.0)["cameras"]["ptz1"]["preview"]["kind"] == "preview"
    assert state.preview_jpeg("ptz1") == b"later"
    # the detections may be handled before their snapshot (each key has its own thread)
    state.on_message(m.MarkerDetections(measured_s=7.0, camera="ptz1", status="ok",
                                        threshold=230, width_px=704, height_px=576,
                                        markers=[marker]))
    state.on_message(shot.model_copy(update={"measured_s": 7.0, "seq": 42}))
    assert state.view(8.0)["cameras"]["ptz1"]["preview"]["markers"] == [[100.0, 200.0, 4.0]]


@pytest.fixture
def server(tmp_path: Path) -> Iterator[tuple[WebServer, Path]]:
    state = LiveState()
    state.on_message(_robot(1.0, 5.0))
    crater = CraterImage(tmp_path / "crater.npz", retry_s=0.0)
    app = build_app(Gate(None, 3600, tls=False), lambda: state.view(2.0), state.preview_jpeg,
                    state.video_jpeg, crater, push_period_s=0.05, max_streams=10)
    web = WebServer(app, "127.0.0.1", 0).start()
    yield web, tmp_path / "crater.npz"
    web.close()


def _get(web: WebServer, path: str) -> tuple[int, bytes, str]:
    try:
        with urllib.request.urlopen(f"http://127.0.0.1:{web.port}{path}", timeout=5) as reply:
            return reply.status, reply.read(), reply.headers["Content-Type"]
    except urllib.error.HTTPError as err:
        return err.code, b"", ""


def test_a_cameras_collection_shows_its_progress_and_why_it_failed() -> None:
    state = LiveState()
    state.on_message(m.CollectProgress(measured_s=0.0, camera="ptz1", state="collecting",
                                       passpoints=0, target=100, snapshots=0, skipped={}))
    state.on_message(m.CollectProgress(measured_s=10.0, camera="ptz1", state="collecting",
                                       passpoints=34, target=100, snapshots=80,
                                       skipped={"no marker": 40, "moving": 6}))
    assert state.view(11.0)["cameras"]["ptz1"]["calibration"] == {
        "state": "collecting", "passpoints": 34, "target": 100, "message": "",
        "snapshots": 80, "skipped": {"no marker": 40, "moving": 6},
        "time_left_s": pytest.approx(66 * 10 / 34, abs=0.1), "mean_error_px": None}
    why = "no passpoint for 60 s (34 of 100; since the last: 600 no marker)"
    state.on_message(m.CollectProgress(measured_s=70.0, camera="ptz1", state="failed",
                                       passpoints=34, target=100, snapshots=680,
                                       skipped={"no marker": 600}, message=why))
    shown = state.view(71.0)["cameras"]["ptz1"]
    assert shown["calibration"]["state"] == "failed" and shown["calibration"]["message"] == why
    assert shown["position"] is None, "uncalibrated: no pose"
    assert shown["calibration"]["time_left_s"] is None
    alarms = state.view(72.0)["alarms"]["active"]
    assert alarms == [{"cause": "calibration failed", "detail": f"ptz1: {why}",
                       "since_s": 71.0}]


def test_the_server_serves_the_page_the_state_and_events(server: tuple) -> None:
    web, _ = server
    status, body, kind = _get(web, "/")
    assert status == 200 and b"<canvas id=\"map\"" in body and kind.startswith("text/html")
    assert _get(web, "/app.js")[0] == 200
    assert json.loads(_get(web, "/state.json")[1])["robot"]["x_mm"] == 5.0
    with urllib.request.urlopen(f"http://127.0.0.1:{web.port}/events", timeout=5) as reply:
        assert reply.headers["Content-Type"].startswith("text/event-stream")
        first = reply.readline()
        assert first.startswith(b"data: ") and json.loads(first[6:])["robot"]["x_mm"] == 5.0


def test_unknown_paths_and_cameras_are_404(server: tuple) -> None:
    web, _ = server
    for path in ("/nothing", "/preview/ptz1.jpg", "/preview/../etc/passwd.jpg",
                 "/static/../settings.py"):
        assert _get(web, path)[0] == 404, path


def test_the_height_map_appears_once_the_sim_has_written_it(server: tuple) -> None:
    web, crater_file = server
    crater = CraterImage(crater_file)
    assert crater.waiting_for().startswith(f"waiting for the crater height map {crater_file}")
    assert json.loads(_get(web, "/map.json")[1])["image"] is False
    assert _get(web, "/map.png")[0] == 404
    heights = np.zeros((30, 40), dtype=np.float32)
    heights[10:20, 10:30] = -500.0
    HeightMap(heights, -2000.0, -1500.0, 100.0).save(crater_file)
    assert crater.waiting_for() == ""
    assert CraterImage(None).waiting_for() == "", "no map asked for: nothing to wait for"
    info = json.loads(_get(web, "/map.json")[1])
    assert info["extent_mm"] == [-2000.0, 1900.0, -1500.0, 1400.0] and info["image"] is True
    assert info["height_mm"] == [-500.0, 0.0], "the colour scale's ends"
    assert len(info["colours"]) == 11 and all(c.startswith("#") for c in info["colours"])
    status, png, kind = _get(web, "/map.png")
    assert status == 200 and png.startswith(b"\x89PNG") and kind == "image/png"


def test_memory_stays_flat_under_key_churn() -> None:
    """Valid messages under thousands of made-up camera and service names (a fuzzer's key
    churn) keep at most MAX_* of each; the lab's own, heard all along, stay."""
    import tracemalloc

    from services.web.state import MAX_CAMERAS, MAX_SERVICES

    state = LiveState()
    jpeg = bytes(100_000)

    def preview(camera: str) -> m.PtzPreview:
        return m.PtzPreview(measured_s=1.0, camera=camera, seq=1, width_px=704, height_px=576,
                            jpeg=jpeg + camera.encode(), pan_deg=0, tilt_deg=0, markers=[])

    def health(service: str) -> m.ServiceHealth:
        return m.ServiceHealth(measured_s=1.0, service=service, instance="main", host="h",
                               pid=1, started_s=0.0, status="ok", keys={})

    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        for i in range(2000):
            state.on_message(preview(f"fuzz{i}"))
            state.on_message(health(f"fuzz{i}"))
            state.on_alive(f"fuzz{i}", "main", True)
            if i % 5 == 0:  # the lab's own keep talking
                state.on_message(preview("ptz1"))
                state.on_message(health("gantry"))
                state.on_alive("gantry", "main", True)
        grown = tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()
    assert len(state.previews) <= MAX_CAMERAS and len(state.health) <= MAX_SERVICES
    assert len(state.seen) <= MAX_SERVICES and len(state.alive) <= MAX_SERVICES
    assert "ptz1" in state.previews and ("gantry", "main") in state.health
    assert ("gantry", "main") in state.alive
    assert grown < (MAX_CAMERAS + 4) * len(jpeg), f"grew {grown / 1e6:.1f} MB"
    assert len(state.view(2.0)["services"]) <= MAX_SERVICES
