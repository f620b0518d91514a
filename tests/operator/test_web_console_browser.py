"""The operator's console in a real browser (headless chromium) against a live lab: sign in as
operator, calibrate ptz1 from the page and accept the pose, hold ptz2 and steer it by hand,
let it follow again, record 20 s and open the recording's report; a viewer sees it all greyed
out. The lab: router, sim (the calibration wand moves, the robot waits), tracker, calib, both
PTZ cameras (poses stored) and the page with its users."""

from __future__ import annotations

import signal
from collections.abc import Iterator

import pytest

from common import keys
from common import messages as m
from common.bus import Bus
from tests.conftest import client_settings, stb_process, wait_for
from tests.operator.test_web import chromium, sign_in
from tests.services.test_processes import _open_when_up, _stop
from tests.uplab import OPERATOR, VIEWER, write_up_lab

RECORD_S = 20


@pytest.fixture(scope="module")
def console_lab(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict]:
    tmp = tmp_path_factory.mktemp("console")
    services = ["router", "sim", "tracker", "calib", "ptz:ptz1", "ptz:ptz2", "web"]
    lab, endpoint, port = write_up_lab(tmp, services, users=True)
    with open(lab, "a") as f:  # the wand all along; a short collection from the page
        f.write("calibration_count = 30\n")
    text = lab.read_text().replace("[sim]\n", '[sim]\nscenario = "calibration"\n', 1)
    lab.write_text(text)
    up = stb_process("up", "--lab", str(lab), "--no-view")
    session = None
    try:
        session = _open_when_up(endpoint)
        bus = Bus(session, client_settings(endpoint))
        poses: list[m.CameraPose] = []
        states: dict[str, m.PtzState] = {}
        truth: dict[str, m.PtzTruth] = {}
        bus.subscribe(keys.CALIB_POSE, poses.append, latest=False)
        bus.subscribe(keys.PTZ_STATE, lambda s: states.__setitem__(s.camera, s), latest=False)
        bus.subscribe(keys.TRUTH_PTZ, lambda t: truth.__setitem__(t.camera, t), latest=False)
        wait_for(lambda: {"ptz1", "ptz2"} <= states.keys(), timeout=60, period=0.3)
        with chromium() as browser:
            yield {"url": f"http://127.0.0.1:{port}", "browser": browser, "poses": poses,
                   "states": states, "truth": truth, "tmp": tmp}
    finally:
        if session is not None:
            session.close()
        _stop(up, signal.SIGINT, timeout=30)


@pytest.fixture(scope="module")
def operator_tab(console_lab: dict) -> Iterator[object]:
    tab = console_lab["browser"].new_page(viewport={"width": 1400, "height": 900})
    sign_in(tab, console_lab["url"], OPERATOR)
    wait_for(lambda: tab.locator("#camera-ptz1 [data-command='calib-start']").count() == 1,
             timeout=20)
    yield tab
    tab.close()


def _click(tab: object, camera: str, command: str) -> None:
    tab.click(f"#camera-{camera} [data-command='{command}']")  # type: ignore[attr-defined]


@pytest.mark.system
@pytest.mark.timeout(300)
def test_calibrate_a_camera_from_the_page_and_accept_the_pose(console_lab: dict,
                                                              operator_tab: object) -> None:
    tab, poses = operator_tab, console_lab["poses"]
    heard = len(poses)
    _click(tab, "ptz1", "calib-start")
    progress = tab.locator("#camera-ptz1 .progress-text")  # type: ignore[attr-defined]
    wait_for(lambda: "calibrating:" in progress.inner_text(), timeout=30, period=0.5)
    accept = tab.locator("#camera-ptz1 [data-command='calib-accept']")  # type: ignore[attr-defined]
    wait_for(lambda: accept.is_visible(), timeout=180, period=0.5)
    assert progress.inner_text().startswith("calibrated:") and "accept or discard" in \
        progress.inner_text()
    assert not [p for p in poses[heard:] if p.camera == "ptz1"], "held: not taken yet"
    accept.click()
    wait_for(lambda: [p for p in poses[heard:] if p.camera == "ptz1"], timeout=10)
    wait_for(lambda: not accept.is_visible(), timeout=5)  # the page has heard it done


@pytest.mark.system
def test_hold_a_camera_steer_it_by_hand_and_let_it_follow(console_lab: dict,
                                                         operator_tab: object) -> None:
    tab, states, truth = operator_tab, console_lab["states"], console_lab["truth"]
    _click(tab, "ptz2", "ptz-hold")
    wait_for(lambda: states["ptz2"].status == "held" and states["ptz2"].held_by.startswith(
        "olga (web "), timeout=10)
    # held, it comes to rest where its last command sent it: start from there
    wait_for(lambda: abs(states["ptz2"].pan_deg - truth["ptz2"].pan_deg) < 0.2, timeout=10)
    before = last = states["ptz2"].pan_deg
    answer = tab.locator("#camera-ptz2 .answer")  # type: ignore[attr-defined]
    for _ in range(3):  # three presses of ◀, each 5° from wherever the camera is
        _click(tab, "ptz2", "ptz-left")
        def stepped(p: float = last) -> bool:
            return abs(states["ptz2"].pan_deg - (p - 5.0)) < 0.3

        wait_for(stepped, timeout=10,
                 why=lambda: f"{answer.inner_text()!r}, pan {states['ptz2'].pan_deg:.1f}")
        last = states["ptz2"].pan_deg
    assert before - last == pytest.approx(15.0, abs=2.0), "three steps of 5° to the left"
    assert states["ptz2"].status == "held", "the operator's moves are no one else's hand"
    _click(tab, "ptz2", "ptz-follow")
    wait_for(lambda: states["ptz2"].status in ("tracking", "idle") and
             abs(truth["ptz2"].pan_deg - before) < 2.0, timeout=15)


@pytest.mark.system
@pytest.mark.timeout(420)
def test_record_twenty_seconds_and_open_the_report(console_lab: dict,
                                                   operator_tab: object) -> None:
    tab = operator_tab
    tab.fill("#record-seconds", "")  # type: ignore[attr-defined]
    tab.click("#record-start")  # type: ignore[attr-defined]
    now = tab.locator("#record-now")  # type: ignore[attr-defined]
    name = wait_for(lambda: now.get_attribute("data-recording"), timeout=10)
    # `stb record` starting up (a CI run: over 20 s beside the other worker, so a stop after
    # the page's 20 s came while it still imported), then recording
    wait_for(lambda: now.text_content().startswith("recording"), timeout=90, period=0.5)
    wait_for(lambda: float(now.get_attribute("data-elapsed") or 0) >= RECORD_S,
             timeout=RECORD_S + 10, period=0.5)  # the page's own clock of the recording
    tab.click("#record-stop")  # type: ignore[attr-defined]
    wait_for(lambda: now.get_attribute("data-recording") == "", timeout=30)
    link = tab.locator(f"#recordings tr[data-recording='{name}'] a")  # type: ignore[attr-defined]
    row = tab.locator(f"#recordings tr[data-recording='{name}']")  # type: ignore[attr-defined]
    wait_for(lambda: link.count() == 1, timeout=180, period=1.0,
             why=lambda: f"the row reads {row.all_text_contents()}")
    with tab.expect_popup() as opened:  # type: ignore[attr-defined]
        link.click()
    report = opened.value
    report.wait_for_load_state()
    assert report.locator("img").count() >= 2, "the report's plots"
    assert (console_lab["tmp"] / "recordings" / f"{name}.mcap").stat().st_size > 100_000
    report.close()


@pytest.mark.system
def test_a_viewer_sees_every_console_control_greyed_out(console_lab: dict) -> None:
    tab = console_lab["browser"].new_page(viewport={"width": 1400, "height": 900})
    try:
        sign_in(tab, console_lab["url"], VIEWER)
        controls = tab.locator("#camera-ptz1 [data-command], #record-start, #record-stop")
        wait_for(lambda: controls.count() >= 10, timeout=20)
        assert all(controls.nth(i).is_disabled() for i in range(controls.count()))
        status = tab.evaluate("""async () => {
            const me = await (await fetch("session.json")).json();
            const r = await fetch("ptz/ptz1/hold", {method: "POST",
                                                    headers: {"X-CSRF-Token": me.csrf}});
            return r.status; }""")
        assert status == 403
    finally:
        tab.close()
