"""The operator's page phase by phase, in headless chromium: the web service under ``stb up``
with its router, fed over Zenoh what the services would publish — before anything arrives,
while a camera calibrates, while the crane follows with alarms, after an alarm clears — with a
screenshot of each phase and assertions on what is visible; and the layout at 1400×900 and
1280×720. Each test has a tab of its own and publishes what its phase needs, so they pass in
any order; the first, before any data, has a page service of its own. (The whole lab's page,
buttons to the real gantry included, is ``test_web.py``.)"""

from __future__ import annotations

import contextlib
import functools
import json
import os
import signal
import time
import urllib.request
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pytest

from common import keys
from common import messages as m
from common.bus import Bus
from services.sim.world import CraterShape, generate_crater
from tests.conftest import client_settings, stb_process, wait_for
from tests.operator.test_web import chromium
from tests.services.test_processes import _open_when_up, _stop
from tests.uplab import write_up_lab

SHOTS = os.environ.get("STB_PAGE_SCREENSHOTS")
"""A folder to keep the phases' screenshots in (docs/figures has one of them)."""


@dataclass
class Quiet:
    bus: Bus
    url: str
    shots: Path


@contextlib.contextmanager
def _page_lab(tmp: Path) -> Iterator[Quiet]:
    """``stb up`` with the router and the page, nothing else: the test plays the services."""
    lab, endpoint, port = write_up_lab(tmp, ["router", "web"])
    generate_crater(CraterShape(), np.random.default_rng(1)).save(tmp / "crater.npz")
    up = stb_process("up", "--lab", str(lab), "--no-view")
    session = None
    try:
        session = _open_when_up(endpoint)
        url = f"http://127.0.0.1:{port}"

        def answers() -> bool:
            try:
                with urllib.request.urlopen(f"{url}/state.json", timeout=2):
                    return True
            except OSError:
                return False

        wait_for(answers, timeout=30, period=0.3)
        yield Quiet(Bus(session, client_settings(endpoint)), url,
                    Path(SHOTS) if SHOTS else tmp)
    finally:
        if session is not None:
            session.close()
        _stop(up, signal.SIGINT, timeout=20)


@pytest.fixture(scope="module")
def quiet(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Quiet]:
    with _page_lab(tmp_path_factory.mktemp("page")) as lab:
        yield lab


@pytest.fixture(scope="module")
def browser() -> Iterator[object]:
    with chromium() as launched:
        yield launched


@contextlib.contextmanager
def _tab(browser: object, quiet: Quiet) -> Iterator[object]:
    page = browser.new_page(viewport={"width": 1400, "height": 900})  # type: ignore[attr-defined]
    try:
        page.goto(quiet.url, wait_until="load")
        wait_for(lambda: _text(page, "#connection") == "live", timeout=10)
        yield page
    finally:
        page.close()


@pytest.fixture
def tab(browser: object, quiet: Quiet) -> Iterator[object]:
    with _tab(browser, quiet) as page:
        yield page


def _text(page: object, selector: str) -> str:
    return page.locator(selector).inner_text()  # type: ignore[attr-defined]


def _showing(page: object, selector: str, needle: str) -> str | None:
    """The element's text once it shows ``needle`` (None before)."""
    text = _text(page, selector)
    return text if needle in text else None


def _colours(page: object, selector: str) -> int:
    """How many different colours a canvas shows (a blank one: 1)."""
    return page.evaluate(  # type: ignore[attr-defined]
        """(sel) => { const c = document.querySelector(sel);
             const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
             const seen = new Set();
             for (let i = 0; i < d.length; i += 4 * 7)
               seen.add(d[i] << 16 | d[i+1] << 8 | d[i+2] | d[i+3] << 24);
             return seen.size; }""", selector)


def _shot(page: object, quiet: Quiet, name: str) -> Path:
    path = quiet.shots / f"page-{name}.png"
    page.screenshot(path=str(path))  # type: ignore[attr-defined]
    assert path.stat().st_size > 20_000, "a screenshot with something on it"
    return path


def _health(quiet: Quiet, service: str, status: str, detail: str = "") -> None:
    quiet.bus.publish(keys.HEALTH, m.ServiceHealth(
        measured_s=time.time(), service=service, instance="main", host="h", pid=1,
        started_s=time.time() - 10, status=status, detail=detail, keys={}),  # type: ignore[arg-type]
        service=service, instance="main")


def _progress(quiet: Quiet, camera: str, state: str, passpoints: int, message: str = "",
              at: float | None = None) -> None:
    quiet.bus.publish(keys.CALIB_PROGRESS, m.CollectProgress(
        measured_s=time.time() if at is None else at, camera=camera, state=state,  # type: ignore[arg-type]
        passpoints=passpoints, target=40, snapshots=3 * passpoints,
        skipped={"no marker": 2 * passpoints}, message=message), camera=camera)


def _crane(quiet: Quiet, x: float, mode: str = "armed", status: str = "tracking",
           at: float | None = None) -> None:
    quiet.bus.publish(keys.GANTRY_STATE, m.CraneState(
        measured_s=at or time.time(), status=status, x_mm=x, y_mm=0.0,  # type: ignore[arg-type]
        target_x_mm=x, target_y_mm=0.0, enabled=True, moving=True, fault_bits=0, mode=mode,  # type: ignore[arg-type]
        mode_by="operator", mode_reason="run 3"))


def _offload(quiet: Quiet, error_mm: float, at: float | None = None) -> None:
    share = 100 * error_mm / 2000
    quiet.bus.publish(keys.GANTRY_OFFLOAD, m.GravityOffload(
        measured_s=at or time.time(), horizontal_error_mm=error_mm, cable_length_mm=2000.0,
        vertical_loss_pct=0.1, horizontal_share_pct=share, warning=share > 5.0,
        warn_above_pct=5.0))


def _robot(quiet: Quiet, x: float, at: float | None = None) -> None:
    quiet.bus.publish(keys.TRACKER_ROBOT, m.RobotPosition(
        measured_s=at or time.time(), x_mm=x, y_mm=0.0, z_mm=0.0, vx_mm_s=100.0, vy_mm_s=0.0,
        vz_mm_s=0.0))


def _state(quiet: Quiet) -> dict:
    with urllib.request.urlopen(f"{quiet.url}/state.json", timeout=2) as answer:
        return json.load(answer)


def _page_has(quiet: Quiet, sample: tuple[float, float, float]) -> bool:
    """Whether the page's latest (robot x, crane x, crane's error) is ``sample``."""
    state = _state(quiet)
    return ((state["robot"] or {}).get("x_mm"), (state["crane"] or {}).get("x_mm"),
            (state["offload"] or {}).get("horizontal_error_mm")) == sample


def _gantry_samples(quiet: Quiet, samples: list[tuple[float, float, float]]) -> None:
    """The gantry's cycles as (robot x, crane x, crane's error) a fifth of a second apart (as
    the gantry sends them), the last stamped now; each published once the page has the one
    before (the page keeps the latest of each key: a burst would reach it as its last)."""
    now = time.time()
    for i, sample in enumerate(samples):
        at = now - 0.2 * (len(samples) - 1 - i)
        _robot(quiet, sample[0], at=at)
        _crane(quiet, sample[1], at=at)
        _offload(quiet, sample[2], at=at)
        wait_for(functools.partial(_page_has, quiet, sample), timeout=10)


def test_1_before_any_data_every_panel_says_what_it_waits_for(
        browser: object, tmp_path: Path) -> None:
    with _page_lab(tmp_path) as untouched, _tab(browser, untouched) as tab:
        _before_any_data(tab, untouched)


def _before_any_data(tab: object, quiet: Quiet) -> None:
    def waiting(panel: str) -> str:  # "connecting to the web service…" until its first state
        return tab.locator(panel).get_attribute("data-waiting") or ""  # type: ignore[attr-defined]
    wait_for(lambda: "waiting for the robot" in waiting("#map"), timeout=10,
             why=lambda: f"the map says {waiting('#map')!r}")
    wait_for(lambda: "waiting for the gantry's offload" in waiting("#plot"), timeout=5,
             why=lambda: f"the plot says {waiting('#plot')!r}")
    assert "waiting for the PTZ cameras" in _text(tab, "#cameras")
    assert _text(tab, "#alarms").startswith("no alarm") or "service" in _text(tab, "#alarms")
    # The crater is drawn with its axes and colour scale before any robot: never a blank map.
    wait_for(lambda: tab.evaluate("mapReady"), timeout=10)  # type: ignore[attr-defined]
    assert _colours(tab, "#map") > 200
    _shot(tab, quiet, "1-waiting")


def test_2_calibration_progress_per_camera(tab: object, quiet: Quiet) -> None:
    started = time.time() - 30
    _progress(quiet, "ptz1", "collecting", 0, at=started)
    _progress(quiet, "ptz1", "collecting", 12)  # 12 in 30 s: 28 more take about 70 s
    quiet.bus.publish(keys.PTZ_STATE, m.PtzState(
        measured_s=time.time(), camera="ptz1", status="calibrating", pan_deg=10.0,
        tilt_deg=-20.0, zoom=1, focal_px=743.1, aim_error_deg=0.0), camera="ptz1")
    picture = np.full((576, 704), 40, np.uint8)
    cv2.circle(picture, (300, 200), 6, 255, -1)  # the wand's marker
    jpeg = cv2.imencode(".jpg", picture)[1].tobytes()
    taken = time.time()
    quiet.bus.publish(keys.PTZ_SNAPSHOT, m.CameraFrame(
        measured_s=taken, camera="ptz1", seq=9, width_px=704, height_px=576, encoding="jpeg",
        data=jpeg), camera="ptz1")
    canvas = tab.locator("#camera-ptz1 canvas")  # type: ignore[attr-defined]
    # the page may draw the snapshot before its markers arrive (they come on their own key):
    # here it does, and it must draw the markers over it when they come
    wait_for(lambda: canvas.get_attribute("data-seq") == "snapshot-9", timeout=5)
    assert canvas.get_attribute("data-markers") == "0"
    quiet.bus.publish(keys.PTZ_DETECTIONS, m.MarkerDetections(
        measured_s=taken, camera="ptz1", status="ok", threshold=230, width_px=704,
        height_px=576, markers=[m.DetectedMarker(
            u_px=300.0, v_px=200.0, radius_long_px=6.0, radius_short_px=6.0, angle_deg=0.0,
            roundness=1.0, area_px=113)]), camera="ptz1")
    text = wait_for(lambda: _showing(tab, "#camera-ptz1", "12 of 40"), timeout=5)
    wait_for(lambda: canvas.get_attribute("data-markers") == "1", timeout=5)
    assert canvas.get_attribute("data-kind") == "calibration snapshot"
    assert "calibrating: 12 of 40 passpoints" in text and "passed over: no marker 24" in text
    left = float(text.split("about ")[1].split(" s left")[0])
    assert 60 <= left <= 80, text
    width = tab.evaluate(  # type: ignore[attr-defined]
        "document.querySelector('#camera-ptz1 .bar div').style.width")
    assert width == "30%"
    assert "aim error" not in text, "no aim error while calibrating"
    _shot(tab, quiet, "2-calibrating")


def test_3_following_with_alarms_in_the_banner_and_the_plot(tab: object, quiet: Quiet) -> None:
    _progress(quiet, "ptz2", "failed", 0, message="no passpoint for 60 s: no marker in 40 "
              "of 40 snapshots")
    _health(quiet, "tracker", "degraded", "QTM answers slowly")  # no such service alive
    # 3 s of a crane falling behind: 40 → 190 mm off
    _gantry_samples(quiet, [(100.0 * i, 100.0 * i - 40 - 10 * i, 40.0 + 10 * i)
                            for i in range(16)])
    banner = wait_for(lambda: _showing(tab, "#alarms", "sideways pull"), timeout=5)
    causes = tab.eval_on_selector_all(  # type: ignore[attr-defined]
        "#alarms .alarm", "els => els.map(e => e.dataset.cause)")
    assert {"sideways pull", "calibration failed", "service down"} <= set(causes), causes
    assert "(limit 5 %)" in banner and "ptz2: no passpoint for 60 s" in banner
    assert "tracker/main is gone" in banner
    assert tab.locator("#alarms").get_attribute("class") == "on"  # type: ignore[attr-defined]
    # the plot draws on its own tick, after the banner: wait for it (a clean-clone run read
    # 2 points the moment the banner showed)
    plot = tab.locator("#plot")  # type: ignore[attr-defined]
    wait_for(lambda: int(plot.get_attribute("data-points") or 0) >= 3, timeout=5,
             why=lambda: f"{plot.get_attribute('data-points')} points in the plot")
    assert plot.get_attribute("data-waiting") == ""
    assert "uncalibrated: no passpoint for 60 s" in _text(tab, "#camera-ptz2")
    assert "waiting for ptz2's first preview" in tab.locator(  # type: ignore[attr-defined]
        "#camera-ptz2 canvas").get_attribute("data-waiting"), "never a blank picture"
    assert _text(tab, "#gantry-pill") == "gantry: armed, tracking"
    assert "sideways pull" in _text(tab, "#offload") and "(limit 5 %)" in _text(tab, "#offload")
    _shot(tab, quiet, "3-alarms")


def test_4_an_alarm_that_clears_leaves_the_banner_and_is_listed(tab: object,
                                                                 quiet: Quiet) -> None:
    # the crane 200 mm behind: the sideways-pull alarm
    _gantry_samples(quiet, [(100.0 * i, 100.0 * i - 200, 200.0) for i in range(5)])
    wait_for(lambda: "sideways pull" in _text(tab, "#alarms"), timeout=10)
    # a second of the crane back on the robot
    _gantry_samples(quiet, [(500.0 + 100.0 * i, 500.0 + 100.0 * i - 30, 30.0) for i in range(5)])
    wait_for(lambda: "sideways pull" not in _text(tab, "#alarms"), timeout=10)
    wait_for(lambda: "sideways pull" in _text(tab, "#ended"), timeout=10)
    _crane(quiet, 0.0, mode="stopped", status="stopped")
    wait_for(lambda: "gantry stopped" in _text(tab, "#alarms"), timeout=10)
    assert "run 3 (operator): reset, then arm" in _text(tab, "#alarms")
    _shot(tab, quiet, "4-cleared")


@pytest.mark.parametrize("width,height", [(1400, 900), (1280, 720)])
def test_the_page_fits_the_screen(browser: object, quiet: Quiet, width: int,
                                  height: int) -> None:
    """At 1400×900 everything is on one screen; at 1280×720 the map, the alarms, the gantry's
    buttons and both previews still are (the side column scrolls within itself)."""
    page = browser.new_page(viewport={"width": width, "height": height})  # type: ignore[attr-defined]
    try:
        page.goto(quiet.url, wait_until="load")
        _progress(quiet, "ptz1", "collecting", 5)
        _progress(quiet, "ptz2", "collecting", 5)
        wait_for(lambda: page.locator("#camera-ptz2").count() == 1, timeout=5)
        page.wait_for_timeout(300)
        size = page.evaluate("[document.documentElement.scrollWidth, "
                             "document.documentElement.scrollHeight]")
        assert size[0] <= width and size[1] <= height, f"the page scrolls: {size}"
        must = ["#map", "#plot", "#alarms", "#camera-ptz1 canvas", "#camera-ptz2 canvas",
                "button[data-command='stop']", "button[data-command='arm']", "#gantry-mode"]
        if width >= 1400:
            must += ["#offload", "#services"]
        for selector in must:
            box = page.locator(selector).bounding_box()
            assert box is not None and box["width"] > 40 and box["height"] > 12, selector
            assert box["x"] >= 0 and box["y"] >= 0, selector
            assert box["x"] + box["width"] <= width + 1, (selector, box)
            assert box["y"] + box["height"] <= height + 1, (selector, box)
        previews = [page.locator(f"#camera-{c} canvas").bounding_box() for c in ("ptz1", "ptz2")]
        assert all(p["height"] >= (250 if width >= 1400 else 180) for p in previews), previews
        assert page.locator("#map").bounding_box()["width"] >= (500 if width >= 1400 else 330)
        _shot(page, quiet, f"fit-{width}x{height}")
    finally:
        page.close()
