"""One running simulated lab for the operator's tools (recording, replay, report, web page):
``stb up`` with the router, the sim, tracker, calib (poses stored beforehand, as after a
calibration), both PTZ cameras, the gantry and the web page, on free loopback ports."""

from __future__ import annotations

import signal
import subprocess
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

from common import keys
from common import messages as m
from common.bus import Bus
from services.calib.store import PoseStore
from tests.calib.test_demo_calibration import MOUNTS
from tests.conftest import client_settings, free_port, stb_process, wait_for
from tests.gantry.rig import Operator
from tests.services.test_processes import _open_when_up, _stop
from tests.sim.test_sim_service import write_lab

SERVICES = ["router", "sim", "tracker", "calib", "ptz:ptz1", "ptz:ptz2", "gantry", "web"]


@dataclass
class LiveLab:
    lab: Path
    endpoint: str
    web_url: str
    crater_file: Path
    tmp: Path
    up: subprocess.Popen


def store_poses(data_dir: Path) -> None:
    """The cameras' poses as a finished calibration leaves them on disk."""
    store = PoseStore(data_dir)
    for camera, mount in MOUNTS.items():
        store.save(m.CameraPose(measured_s=time.time(), camera=camera, x_mm=mount.x_mm,
                                y_mm=mount.y_mm, z_mm=mount.z_mm, rx_deg=mount.rx_deg,
                                ry_deg=mount.ry_deg, rz_deg=mount.rz_deg, focal_mm=3.8,
                                mean_error_px=1.5, passpoints=100), {"method": "stored"})


@pytest.fixture(scope="package")
def live_lab(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveLab]:
    tmp = tmp_path_factory.mktemp("live")
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    lab, _ = write_lab(tmp, endpoint, tmp / "crater.npz")
    web_port = free_port()
    services = ", ".join(f'"{s}"' for s in SERVICES)
    with open(lab, "a") as f:
        f.write(f"""
[router]
listen = ["{endpoint}"]
[up]
log_dir = "{tmp / 'logs'}"
services = [{services}]
[web]
port = {web_port}
height_map = "{tmp / 'crater.npz'}"
""")
    store_poses(tmp / "calib")
    up = stb_process("up", "--lab", str(lab), "--no-view")
    session = None
    try:
        session = _open_when_up(endpoint)
        bus = Bus(session, client_settings(endpoint))
        crane: list[m.CraneState] = []
        ptz: dict[str, m.PtzState] = {}
        bus.subscribe(keys.GANTRY_STATE, crane.append, latest=False)
        bus.subscribe(keys.PTZ_STATE, lambda s: ptz.__setitem__(s.camera, s), latest=False)
        operator = Operator(bus)  # the crane moves once an operator arms the gantry
        wait_for(lambda: operator.send("arm").accepted, timeout=40, period=0.5)
        wait_for(lambda: crane and crane[-1].status == "tracking", timeout=40, period=0.2)
        wait_for(lambda: all(ptz.get(c) and ptz[c].status == "tracking" for c in MOUNTS),
                 timeout=20, period=0.2)
        bus.close()
        session.close()
        session = None
        yield LiveLab(lab, endpoint, f"http://127.0.0.1:{web_port}", tmp / "crater.npz", tmp, up)
    finally:
        if session is not None:
            session.close()
        if up.poll() is None:
            _stop(up, signal.SIGINT, timeout=20)
