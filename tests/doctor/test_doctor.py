"""``stb doctor`` against the whole simulated lab under ``stb up``: every check passes, and
each of six faults — a motion-capture label the lab file names but QTM has not, a camera that
does not answer, a register map that does not fit the PLC, a host whose clock is 0.5 s off, a
nearly full disk, an access-control rule missing — fails its own row, names the fix, and
makes the exit status 1. One lab for the module; each fault is a copy of its lab file with one
change (or, for the clock, a host that publishes its health with a clock 0.5 s ahead).

The sim's devices answer on processor time the lab leaves them (its observation camera renders
only on what nobody else wants, as a real one on its own processor), so on a busy machine one
may miss the doctor's answer time once: the lab here gives each device 30 s, and a fault's
doctor is run again until its row is the only one failing (each run must fail that row)."""

from __future__ import annotations

import json
import re
import shlex
import signal
import subprocess
import sys
import threading
import time
import tomllib
from collections.abc import Callable, Iterator

import pytest
import tomli_w

from common import keys
from common import messages as m
from common.bus import Bus, open_session
from services.deploy.render import cameras_of, router_config
from tests.conftest import ROOT, client_settings, stb_process, wait_for
from tests.ports import free_port
from tests.services.test_processes import _stop
from tests.smalldisk import NO_TMPFS
from tests.uplab import OPERATOR, SERVICES, VIEWER, write_up_lab
from tests.webpage import PageClient

pytestmark = [pytest.mark.system, pytest.mark.timeout(600)]
DEVICE_TIMEOUT_S = 30.0


@pytest.fixture(scope="module")
def lab(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict]:
    folder = tmp_path_factory.mktemp("doctor")
    path, endpoint, web_port = write_up_lab(folder, SERVICES, users=True)
    up = stb_process("up", "--lab", str(path), "--no-view")
    doc = tomllib.loads(path.read_text())
    doc.setdefault("doctor", {})["timeout_s"] = DEVICE_TIMEOUT_S
    try:
        yield {"folder": folder, "lab": path, "endpoint": endpoint, "web_port": web_port,
               "doc": doc}
    finally:
        assert _stop(up, signal.SIGINT, timeout=30) == 0


def _doctor(lab: dict, changes: dict | None = None, name: str = "lab") -> tuple[int, dict]:
    """``stb doctor --json`` on the lab file with ``changes`` merged into its sections; the
    exit status and the rows by name."""
    doc = json.loads(json.dumps(lab["doc"]))
    for section, values in (changes or {}).items():
        target = doc
        for part in section.split("."):
            target = target.setdefault(part, {})
        target.update(values)
    path = lab["folder"] / f"{name}.toml"
    path.write_text(tomli_w.dumps(doc))
    done = subprocess.run([sys.executable, "-m", "services.cli", "doctor", "--lab", str(path),
                           "--json"], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert done.returncode in (0, 1), done.stderr
    return done.returncode, {row["name"]: row for row in json.loads(done.stdout)}


def _healthy(lab: dict) -> tuple[int, dict]:
    """The doctor once the lab is up (services start, the sim's frames come, calib answers)."""
    result: list[tuple[int, dict]] = []
    def passed() -> bool:
        result.append(_doctor(lab))
        return result[-1][0] == 0

    wait_for(passed, timeout=120, period=1)
    return result[-1]


def test_the_running_lab_passes_every_check(lab: dict) -> None:
    code, rows = _healthy(lab)
    assert code == 0, rows
    assert {r["verdict"] for r in rows.values()} <= {"pass", "skip"}
    for row in ("motion capture", "PTZ camera ptz1", "PTZ camera ptz2", "crane controller",
                "observation camera", "tracking camera", "clocks", "pose of ptz1",
                "pose of ptz2", "disk for recordings"):
        assert rows[row]["verdict"] == "pass", rows[row]
    assert "AXIS" in rows["PTZ camera ptz1"]["found"]
    assert rows["router access control"]["verdict"] == "skip"  # stb up's open bus


def _fails(run: Callable[[], tuple[int, dict]], name: str, fix: str) -> dict:
    """The rows of a doctor (``run``) that fails ``name``'s row alone, naming ``fix``: run
    again while another row fails too (a device slow once), each run failing ``name``'s."""
    runs: list[dict] = []

    def others(rows: dict) -> list[dict]:
        return [r for r in rows.values() if r["verdict"] == "fail" and r["name"] != name]

    def alone() -> bool:
        code, rows = run()
        assert code == 1, rows
        assert rows[name]["verdict"] == "fail", rows[name]
        assert fix in rows[name]["fix"], rows[name]
        runs.append(rows)
        return not others(rows)

    wait_for(alone, timeout=240, period=1, why=lambda: f"others fail too: {others(runs[-1])}")
    return runs[-1]


def test_a_label_qtm_does_not_have(lab: dict) -> None:
    _healthy(lab)
    rows = _fails(lambda: _doctor(lab, {"tracker": {"robot_label": "rover"}}, "label"),
                  "motion capture", "label the markers in QTM")
    assert "'rover'" in rows["motion capture"]["found"]


def test_a_camera_that_does_not_answer(lab: dict) -> None:
    _healthy(lab)
    dead = f"http://127.0.0.1:{free_port()}"
    _fails(lambda: _doctor(lab, {"ptz.cameras.ptz2": {"url": dead}}, "camera"),
           "PTZ camera ptz2", "[ptz.cameras.ptz2] url")


def test_a_register_map_that_does_not_fit(lab: dict) -> None:
    _healthy(lab)
    _fails(lambda: _doctor(lab, {"gantry.crane": {"word_order": "low_first"}}, "registers"),
           "crane controller", "[gantry.crane.registers]")


def test_a_host_whose_clock_is_half_a_second_ahead(lab: dict) -> None:
    _healthy(lab)
    settings = client_settings(lab["endpoint"])
    session = open_session(settings.zenoh)
    skewed = Bus(session, settings, clock=lambda: time.time() + 0.5)
    stop = time.monotonic() + 300

    def beat() -> None:
        skewed.publish(keys.HEALTH, m.ServiceHealth(
            measured_s=time.time() + 0.5, service="camera", instance="skewed",
            host="camera-pc", pid=1, started_s=time.time(), status="ok", keys={}),
            service="camera", instance="skewed")

    done = threading.Event()

    def beating() -> None:
        while not done.wait(0.2) and time.monotonic() < stop:
            beat()

    thread = threading.Thread(target=beating, daemon=True)
    thread.start()
    try:
        rows = _fails(lambda: _doctor(lab, name="clock"), "clocks", "camera-pc")
    finally:
        done.set()
        thread.join(2)
        skewed.close()
        session.close()
    offset = re.search(r"camera-pc ([+-]\d+) ms", rows["clocks"]["found"])
    assert offset is not None and -550 <= int(offset.group(1)) <= -450, rows["clocks"]


def test_a_nearly_full_disk(lab: dict) -> None:
    _healthy(lab)
    disk = lab["folder"] / "small"
    disk.mkdir(exist_ok=True)
    changes = {"web": {"recordings_dir": str(disk)}, "doctor": {"min_free_gb": 0.01}}
    doc = json.loads(json.dumps(lab["doc"]))
    for section, values in changes.items():
        doc.setdefault(section, {}).update(values)
    path = lab["folder"] / "disk.toml"
    path.write_text(tomli_w.dumps(doc))
    doctor = shlex.join([sys.executable, "-m", "services.cli", "doctor", "--lab", str(path),
                         "--json"])
    where = shlex.quote(str(disk))

    def on_disk(fill_mb: int) -> tuple[int, dict]:
        """The doctor with a 20 MB disk for recordings that has ``fill_mb`` taken."""
        script = (f"mount -t tmpfs -o size=20m tmpfs {where} || exit {NO_TMPFS}; "
                  f"dd if=/dev/zero of={where}/filler bs=1M count={fill_mb} 2>/dev/null; "
                  f"{doctor}")
        done = subprocess.run(["unshare", "-m", "sh", "-c", script], capture_output=True,
                              text=True, timeout=120, cwd=ROOT)
        if done.returncode == NO_TMPFS:
            pytest.skip("no tmpfs can be mounted here")
        return done.returncode, {r["name"]: r for r in json.loads(done.stdout)}

    _, empty = on_disk(0)  # 10 MB asked of the same disk, empty and then nearly full
    assert empty["disk for recordings"]["verdict"] == "pass", empty["disk for recordings"]
    _fails(lambda: on_disk(15), "disk for recordings", "free space there")


def test_an_access_control_rule_missing(lab: dict) -> None:
    _healthy(lab)
    rendered = router_config(cameras_of(["ptz1", "ptz2"]))
    config = lab["folder"] / "router.json5"
    config.write_text(rendered)
    _, rows = _doctor(lab, {"doctor": {"router_config": str(config)}}, "acl-whole")
    assert rows["router access control"]["verdict"] == "pass", rows["router access control"]
    rule = '{ rules: ["ptz2"], subjects: ["ptz2"] },'
    assert rule in rendered
    config.write_text(rendered.replace(rule, ""))
    _fails(lambda: _doctor(lab, {"doctor": {"router_config": str(config)}}, "acl"),
           "router access control", "stb deploy render")


def test_the_page_runs_the_check_for_an_operator_and_shows_it_to_everyone(lab: dict) -> None:
    _healthy(lab)
    page = PageClient(f"http://127.0.0.1:{lab['web_port']}")
    viewer, viewer_csrf, _ = page.sign_in(VIEWER)
    status, _, _ = page.request("POST", "/doctor/run", cookie=viewer,
                                headers={"X-CSRF-Token": viewer_csrf})
    assert status == 403, "a viewer does not start checks"
    operator, csrf, _ = page.sign_in(OPERATOR)
    status, _, body = page.request("POST", "/doctor/run", cookie=operator,
                                   headers={"X-CSRF-Token": csrf})
    assert status == 200 and json.loads(body)["accepted"], body
    views: list[dict] = []

    def finished() -> bool:
        views.append(json.loads(page.request("GET", "/doctor.json", cookie=viewer)[2]))
        return not views[-1]["running"]

    wait_for(finished, timeout=120, period=0.5)
    view = views[-1]
    assert view["exit"] == 0 and view["by"].startswith(OPERATOR[0]), view
    rows = {r["name"]: r["verdict"] for r in view["rows"]}
    assert rows["crane controller"] == "pass" and rows["pose of ptz1"] == "pass", rows
