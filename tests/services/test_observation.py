"""``stb observation`` against the sim's observation camera over VAPIX: the bird's-eye view's
colour JPEGs on stb/video/observation, stamped on arrival; a camera that does not answer makes
the service degraded, naming why, and it carries on."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path

import cv2
import numpy as np
import pytest

from common import keys
from common import messages as m
from common.bus import Bus
from tests.conftest import free_port, stb_process, wait_for
from tests.services.test_processes import _stop
from tests.sim.test_sim_service import sim  # noqa: F401 - a fixture


@pytest.fixture
def observation(sim: dict) -> Iterator[dict]:  # noqa: F811
    proc = stb_process("observation", "--lab", str(sim["lab"]), "--set", "fps=4")
    yield {**sim, "observation": proc}
    _stop(proc)


def test_the_bird_s_eye_view_goes_on_the_bus(observation: dict,
                                             make_bus: Callable[..., Bus]) -> None:
    bus = make_bus()
    frames: list[m.CameraFrame] = []
    health: list[m.ServiceHealth] = []
    bus.subscribe(keys.VIDEO, frames.append, latest=False, camera="observation")
    bus.subscribe(keys.HEALTH, health.append, latest=False, service="observation")
    wait_for(lambda: len(frames) >= 13, timeout=60,
             why=lambda: f"{len(frames)} frames; health {health[-1:]}")
    got = list(frames)
    image = cv2.imdecode(np.frombuffer(got[-1].data, np.uint8), cv2.IMREAD_UNCHANGED)
    assert image is not None and image.shape == (480, 640, 3)
    assert (got[-1].width_px, got[-1].height_px) == (640, 480)
    assert [f.seq for f in got] == sorted(f.seq for f in got)
    stamps = np.array([f.measured_s for f in got])
    assert np.all(np.diff(stamps) > 0)
    # 4 a second over three seconds: each stamped when it arrived, and on a busy machine they
    # arrive in bursts (a CI run: gaps of 0.77 s, then 5 ms), so the mean, not each gap
    assert (stamps[-1] - stamps[0]) / (len(stamps) - 1) == pytest.approx(0.25, abs=0.1)
    wait_for(lambda: any(h.status == "ok" for h in health), timeout=10,
             why=lambda: f"health {health[-1:]}")


def test_a_silent_camera_makes_it_degraded_naming_why(router_endpoint: str, tmp_path: Path,
                                                      make_bus: Callable[..., Bus]) -> None:
    lab = tmp_path / "lab.toml"
    lab.write_text(f'[bus.zenoh]\nconnect = ["{router_endpoint}"]\n'
                   f'[observation]\nurl = "http://127.0.0.1:{free_port()}"\n')
    bus = make_bus()
    health: list[m.ServiceHealth] = []
    bus.subscribe(keys.HEALTH, health.append, latest=False, service="observation")
    proc = stb_process("observation", "--lab", str(lab))
    try:
        wait_for(lambda: any(h.status == "degraded" and "ConnectError" in h.detail
                             for h in health), timeout=30,
                 why=lambda: f"health {health[-1:]}")
        assert proc.poll() is None, "it carries on"
    finally:
        _stop(proc)


def test_a_bad_setting_stops_start_up_naming_the_field() -> None:
    proc = stb_process("observation", "--set", "url=ftp://camera", "--set", "fps=0")
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 2
    assert "observation.url" in err and "observation.fps" in err
