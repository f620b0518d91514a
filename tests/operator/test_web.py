"""The operator's page in a real headless browser (Debian's chromium, driven by Playwright)
against the live sim lab: it loads, shows every service alive, and the robot moves on it."""

from __future__ import annotations

import json
import os
import urllib.error
import urllib.request
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest

from tests.conftest import poll, wait_for
from tests.operator.conftest import LIVE_SERVICES, LiveLab
from tests.uplab import OPERATOR, VIEWER
from tests.webpage import basic

pytestmark = pytest.mark.system  # the whole lab under stb up, armed (make test-system)

CHROMIUM = os.environ.get("STB_CHROMIUM", "/usr/bin/chromium")
FLAGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync"]
"""As root on this machine; without the background-networking flags chromium keeps trying to
reach Google's hosts through the closed network. Playwright adds --headless and a fresh
profile directory of its own."""


def chromium_or_skip() -> str:
    if Path(CHROMIUM).exists():
        return CHROMIUM
    if os.environ.get("STB_REQUIRE_BROWSER"):
        pytest.fail(f"no chromium at {CHROMIUM} (STB_REQUIRE_BROWSER is set: .ci/run installs "
                    "Debian's chromium)")
    pytest.skip(f"no chromium at {CHROMIUM}: apt-get install chromium (.ci/run does)")


@contextmanager
def chromium() -> Iterator[object]:
    """Debian's chromium, headless, driven by Playwright."""
    executable = chromium_or_skip()
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=executable, args=FLAGS)
        try:
            yield browser
        finally:
            browser.close()


def sign_in(tab: object, url: str, user: tuple[str, str]) -> None:
    """Open the page, which shows the sign-in form, and sign in as ``user``."""
    tab.goto(url, wait_until="load")  # type: ignore[attr-defined]
    tab.fill("#user", user[0])  # type: ignore[attr-defined]
    tab.fill("#password", user[1])  # type: ignore[attr-defined]
    tab.click("button[type='submit']")  # type: ignore[attr-defined]
    # the password check and the page's load: seconds on a busy machine (a CI run beside the
    # zoom collection took over 15)
    tab.wait_for_selector("#map", timeout=45_000)  # type: ignore[attr-defined]
    wait_for(lambda: tab.locator("#who").inner_text().startswith(user[0]),  # type: ignore[attr-defined]
             timeout=10)


@pytest.fixture(scope="module")
def browser_() -> Iterator[object]:
    with chromium() as browser:
        yield browser


@pytest.fixture(scope="module")
def page(live_lab: LiveLab, browser_: object) -> Iterator[object]:
    tab = browser_.new_page(viewport={"width": 1400, "height": 900})  # type: ignore[attr-defined]
    sign_in(tab, live_lab.web_url, OPERATOR)
    yield tab
    tab.close()


def _expected_services() -> set[str]:
    out = set()
    for spec in LIVE_SERVICES:
        service, _, instance = spec.partition(":")
        out.add(f"{service}/{instance or 'main'}")
    return out


def test_the_page_shows_every_service_alive(page: object) -> None:
    def alive() -> set[str]:
        rows = page.locator("#services tr[data-alive='true']")  # type: ignore[attr-defined]
        return {rows.nth(i).get_attribute("data-service") for i in range(rows.count())}

    wait_for(lambda: _expected_services() <= alive(), timeout=15, period=0.3)
    assert page.locator("#connection").inner_text() == "live"  # type: ignore[attr-defined]


def test_the_robot_moves_on_the_page_while_the_sim_runs(page: object, live_lab: LiveLab,
                                                         tmp_path: Path) -> None:
    canvas = page.locator("#map")  # type: ignore[attr-defined]
    first = wait_for(lambda: canvas.get_attribute("data-robot-px"), timeout=10)
    a = tuple(map(float, first.split(",")))

    def moved_px() -> float:
        b = tuple(map(float, canvas.get_attribute("data-robot-px").split(",")))
        return ((a[0] - b[0]) ** 2 + (a[1] - b[1]) ** 2) ** 0.5

    wait_for(lambda: moved_px() > 3, timeout=10, period=0.2,
             why=lambda: f"robot drawn at {first}, then {moved_px():.1f} px from there")
    text = page.locator("#robot-xy").inner_text()  # type: ignore[attr-defined]
    assert text.startswith("robot: ") and "mm" in text
    # The page draws what the server says: the robot's canvas position matches its state.
    with urllib.request.urlopen(urllib.request.Request(
            f"{live_lab.web_url}/state.json", headers=basic(VIEWER)), timeout=5) as reply:
        state = json.load(reply)
    assert state["robot"] is not None and len(state["track"]) > 5
    page.screenshot(path=str(tmp_path / "page.png"))  # type: ignore[attr-defined]
    assert (tmp_path / "page.png").stat().st_size > 20_000


def test_camera_previews_the_plot_and_offload_figures_are_shown(page: object,
                                                                 tmp_path: Path) -> None:
    for camera in ("ptz1", "ptz2"):
        preview = page.locator(f"#camera-{camera} canvas")  # type: ignore[attr-defined]

        def shown(p: Any = preview) -> str | None:
            return p.get_attribute("data-seq")

        wait_for(shown, timeout=10)
        caption = page.locator(f"#camera-{camera} .caption").inner_text()  # type: ignore[attr-defined]
        assert "tracking" in caption, caption
    # The robot's IR marker is found in the previews (the sim renders the crater, the robot
    # and its marker; the page draws each detection on the picture).
    wait_for(lambda: any(int(page.locator(f"#camera-{c} canvas").get_attribute(  # type: ignore[attr-defined]
        "data-markers") or 0) for c in ("ptz1", "ptz2")), timeout=10)
    offload = page.locator("#offload").inner_text()  # type: ignore[attr-defined]
    assert "sideways pull" in offload and "%" in offload
    plot = page.locator("#plot")  # type: ignore[attr-defined]
    wait_for(lambda: int(plot.get_attribute("data-points")) >= 3, timeout=10)
    assert page.locator("#alarms").get_attribute("class") in ("on", "none")  # type: ignore[attr-defined]
    shots = Path(os.environ.get("STB_PAGE_SCREENSHOTS") or tmp_path)
    page.screenshot(path=str(shots / "page-following.png"))  # type: ignore[attr-defined]


def test_the_bird_s_eye_view_is_shown_and_follows_the_observation_camera(page: object
                                                                         ) -> None:
    picture = page.locator("#birdseye")  # type: ignore[attr-defined]
    # (one look at both: a newer picture may be loading between two looks)
    wait_for(lambda: picture.evaluate("i => i.complete && [i.naturalWidth, i.naturalHeight]")
             == [640, 480], timeout=20, why=lambda: f"src {picture.get_attribute('src')}")
    first = picture.get_attribute("src")
    wait_for(lambda: picture.get_attribute("src") != first, timeout=10,
             why=lambda: "a newer picture is loaded as it comes")
    assert "640×480" in page.locator("#birdseye-age").inner_text()  # type: ignore[attr-defined]


def test_the_gantry_buttons_stop_reset_and_arm_it(page: object, live_lab: LiveLab) -> None:
    mode = page.locator("#gantry-mode")  # type: ignore[attr-defined]
    answer = page.locator("#gantry-answer")  # type: ignore[attr-defined]
    # The fixture armed the gantry. On the loaded test machine a stall may since have let the
    # crane's watchdog trip, which stops the gantry until an operator resets it (as it must):
    # the buttons take it through stop, reset and arm from either mode.
    wait_for(lambda: mode.inner_text().startswith(("mode: armed", "mode: stopped")), timeout=10)
    for button, expected in (("stop", "mode: stopped"), ("reset", "mode: disarmed"),
                             ("arm", "mode: armed")):
        if button == "stop":  # Stop from the keyboard, anywhere on the page
            page.keyboard.press("Escape")  # type: ignore[attr-defined]
        else:
            page.click(f"button[data-command='{button}']")  # type: ignore[attr-defined]
        if button == "arm":  # after a tripped watchdog, until the controller reports it reset
            _press_until_done(page, answer, button)
        def done(b: str = button) -> bool:
            return bool(answer.inner_text().startswith(f"{b}: done"))

        def in_mode(e: str = expected) -> bool:
            return bool(mode.inner_text().startswith(e))

        wait_for(done, timeout=10)
        wait_for(in_mode, timeout=5)
    assert "(olga (web 127.0.0.1))" in mode.inner_text(), "who armed it, by name"
    history = page.locator("#commands tr[data-by='olga (web 127.0.0.1)']")  # type: ignore[attr-defined]
    wait_for(lambda: history.count() >= 3, timeout=10)
    assert history.first.get_attribute("data-command-row") == "arm"
    with urllib.request.urlopen(urllib.request.Request(
            f"{live_lab.web_url}/state.json", headers=basic(VIEWER)), timeout=5) as reply:
        crane = json.load(reply)["crane"]
    assert crane["mode"] == "armed" and crane["mode_by"] == "olga (web 127.0.0.1)", \
        "the gantry's own state names the operator"
    page.click("button[data-command='reset']")  # type: ignore[attr-defined]
    wait_for(lambda: answer.inner_text().startswith("reset: refused"), timeout=10)
    assert "disarm or stop before a reset" in answer.inner_text(), "the gantry's reason"
    assert mode.inner_text().startswith("mode: armed")


def _press_until_done(page: object, answer: object, button: str) -> None:
    """Press ``button`` again while the gantry refuses it for a fault still reported (the
    controller's next report after a reset clears it), for at most 5 s."""
    def done() -> bool:
        text = wait_for(lambda: answer.inner_text().startswith(f"{button}: ")  # type: ignore[attr-defined]
                        and answer.inner_text(), timeout=10)  # type: ignore[attr-defined]
        if not (text.startswith(f"{button}: refused") and "reset first" in text):
            return True
        page.click(f"button[data-command='{button}']")  # type: ignore[attr-defined]
        return False

    poll(done, timeout=5, period=0.3)  # an operator's pace between presses


def test_without_credentials_everything_answers_401(live_lab: LiveLab) -> None:
    for path in ("/state.json", "/events", "/map.json", "/map.png", "/preview/ptz1.jpg",
                 "/app.js"):
        with pytest.raises(urllib.error.HTTPError) as refused:
            urllib.request.urlopen(f"{live_lab.web_url}{path}", timeout=5)
        assert refused.value.code == 401, path
    for command in ("arm", "disarm", "stop", "reset"):
        request = urllib.request.Request(f"{live_lab.web_url}/gantry/{command}", method="POST")
        with pytest.raises(urllib.error.HTTPError) as refused:
            urllib.request.urlopen(request, timeout=5)
        assert refused.value.code == 401
    with urllib.request.urlopen(live_lab.web_url, timeout=5) as reply:
        form = reply.read()
    assert b'id="signin"' in form and b"canvas" not in form, "only the sign-in form"


def test_a_viewer_sees_the_page_with_every_control_disabled_and_is_refused(
        live_lab: LiveLab, browser_: object) -> None:
    tab = browser_.new_page(viewport={"width": 1400, "height": 900})  # type: ignore[attr-defined]
    try:
        sign_in(tab, live_lab.web_url, VIEWER)
        wait_for(lambda: tab.locator("#connection").inner_text() == "live", timeout=15)
        controls = tab.locator("[data-command]")
        assert controls.count() >= 4
        assert all(controls.nth(i).is_disabled() for i in range(controls.count()))
        # the server refuses too: the viewer's own session, with its CSRF token, from the page
        statuses = tab.evaluate("""async () => {
            const me = await (await fetch("session.json")).json();
            const out = [];
            for (const c of ["arm", "disarm", "stop", "reset"]) {
              const r = await fetch(`gantry/${c}`, {method: "POST",
                                                    headers: {"X-CSRF-Token": me.csrf}});
              out.push(r.status);
            }
            return out; }""")
        assert statuses == [403, 403, 403, 403]
        tab.keyboard.press("Escape")  # no stop from a viewer's keyboard either
    finally:
        tab.close()
    request = urllib.request.Request(f"{live_lab.web_url}/gantry/stop", method="POST",
                                     headers=basic(VIEWER))
    with pytest.raises(urllib.error.HTTPError) as refused:
        urllib.request.urlopen(request, timeout=5)
    assert refused.value.code == 403
