"""One running simulated lab for the operator's tools (recording, replay, report, web page):
``stb up`` with the router, the sim, tracker, calib (poses stored beforehand, as after a
calibration), both PTZ cameras, the gantry and the web page, on free loopback ports."""

from __future__ import annotations

import signal
import subprocess
import tomllib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
import tomli_w

from common import keys
from common import messages as m
from common.bus import Bus
from tests.calib.test_demo_calibration import MOUNTS
from tests.conftest import client_settings, stb_process, wait_for
from tests.gantry.rig import Operator
from tests.services.test_processes import _open_when_up, _stop
from tests.uplab import SERVICES, write_up_lab

LIVE_SERVICES = [*SERVICES, "observation"]
"""The lab the operator's tools are tried on: every service and the bird's-eye view."""


@dataclass
class LiveLab:
    lab: Path
    endpoint: str
    web_url: str
    crater_file: Path
    tmp: Path
    up: subprocess.Popen


@pytest.fixture(scope="package")
def live_lab(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveLab]:
    tmp = tmp_path_factory.mktemp("live")
    lab, endpoint, web_port = write_up_lab(tmp, LIVE_SERVICES, users=True)
    doc = tomllib.loads(lab.read_text())
    # the page's and the recording's pictures show the IR markers only in infrared previews:
    # one every 2 s here (the pointing check's period, 5 min by default), as when watching them
    doc["ptz"]["pointing_infrared_s"] = 2.0
    lab.write_text(tomli_w.dumps(doc))
    up = stb_process("up", "--lab", str(lab), "--no-view")
    session = None
    try:
        session = _open_when_up(endpoint)
        bus = Bus(session, client_settings(endpoint))
        crane: list[m.CraneState] = []
        ptz: dict[str, m.PtzState] = {}
        birds_eye: list[m.CameraFrame] = []
        bus.subscribe(keys.GANTRY_STATE, crane.append, latest=False)
        bus.subscribe(keys.VIDEO, birds_eye.append, latest=False, camera="observation")
        bus.subscribe(keys.PTZ_STATE, lambda s: ptz.__setitem__(s.camera, s), latest=False)
        operator = Operator(bus)  # the crane moves once an operator arms the gantry
        operator.arm_within(40)
        wait_for(lambda: crane and crane[-1].status == "tracking", timeout=40, period=0.2)
        wait_for(lambda: all(ptz.get(c) and ptz[c].status == "tracking" for c in MOUNTS),
                 timeout=20, period=0.2)
        # the recordings expect the bird's-eye view: the observation service is up and sending
        wait_for(lambda: birds_eye, timeout=40, period=0.2,
                 why=lambda: "no bird's-eye picture on video/observation")
        bus.close()
        session.close()
        session = None
        yield LiveLab(lab, endpoint, f"http://127.0.0.1:{web_port}", tmp / "crater.npz", tmp, up)
    finally:
        if session is not None:
            session.close()
        if up.poll() is None:
            _stop(up, signal.SIGINT, timeout=20)
