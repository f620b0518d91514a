"""``stb camera``: frames from an OpenCV source (a video file here) on the bus, stamped when
grabbed, raw or JPEG, and the gantry reads either."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from common import keys
from common import messages as m
from common.bus import Bus
from common.markers import detect
from common.node import Node
from services.camera.service import run
from services.camera.settings import CameraSettings
from services.gantry.frames import decode
from tests.conftest import wait_for
from tests.video import marker_video


@pytest.fixture
def video(tmp_path: Path) -> Path:
    return marker_video(tmp_path / "tracking.avi", 50, (320, 240), (60, 120), 6)


def _frames(settings: CameraSettings, make_bus: Callable[..., Bus], count: int
            ) -> list[m.CameraFrame]:
    """``stb camera`` run until ``count`` of its frames have come over the bus."""
    frames: list[m.CameraFrame] = []
    make_bus().subscribe(keys.GANTRY_FRAME, frames.append, latest=False)
    node = Node("camera", settings, make_bus())
    thread = threading.Thread(target=run, args=(node,), daemon=True)
    thread.start()
    try:
        wait_for(lambda: len(frames) >= count, timeout=15)
    finally:
        node.stop.set()
        thread.join(5)
    return frames


@pytest.mark.parametrize("encoding", ["mono8", "jpeg"])
def test_frames_reach_the_bus_stamped_when_grabbed(video: Path, encoding: str,
                                                   make_bus: Callable[..., Bus]) -> None:
    started = time.time()
    frames = _frames(CameraSettings(source=str(video), encoding=encoding, max_rate_hz=100.0),
                     make_bus, 20)
    assert all(f.encoding == encoding and f.camera == "tracking" for f in frames)
    stamps = [f.measured_s for f in frames]
    assert started - 1 < stamps[0] and stamps == sorted(stamps)
    assert [f.seq for f in frames[:5]] == list(range(5))
    decoded = decode(frames[10])
    assert decoded is not None
    captured, image = decoded
    assert image.shape == (240, 320) and captured == frames[10].measured_s
    found = detect(image)
    assert len(found.markers) == 1, "the gantry finds the marker in it"


def test_a_camera_that_cannot_be_opened_is_reported_not_fatal(
        make_bus: Callable[..., Bus], tmp_path: Path) -> None:
    node = Node("camera", CameraSettings(source=str(tmp_path / "missing.avi")), make_bus())
    thread = threading.Thread(target=run, args=(node,), daemon=True)
    thread.start()
    try:
        wait_for(lambda: node.health().status == "degraded", timeout=6)
        assert "no frames from" in node.health().detail
        assert thread.is_alive()
    finally:
        node.stop.set()
        thread.join(5)


def test_an_exposure_the_source_does_not_take_is_said_and_frames_still_come(
        video: Path, make_bus: Callable[..., Bus], caplog: pytest.LogCaptureFixture) -> None:
    """``exposure_ms`` on a source without exposure control (a file, as a stream would be):
    OpenCV refuses it, the log says the camera keeps its own, and the frames flow."""
    with caplog.at_level("INFO", logger="common.capture"):
        _frames(CameraSettings(source=str(video), exposure_ms=2.0, max_rate_hz=100.0),
                make_bus, 5)
    said = [r.getMessage() for r in caplog.records if r.name == "common.capture"]
    assert any("did not take exposure_ms 2" in line and str(video) in line for line in said), said


def test_a_bad_exposure_stops_the_start_naming_the_field() -> None:
    with pytest.raises(ValueError, match="exposure_ms"):
        CameraSettings(exposure_ms=0.0)
