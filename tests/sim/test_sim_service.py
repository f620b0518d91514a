"""``stb sim`` as a process: every device answers on its protocol, frames and truth on the bus."""

from __future__ import annotations

import asyncio
import signal
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
import qtm_rt
from pymodbus.client import ModbusTcpClient

from common import keys
from common import messages as m
from common.bus import Bus
from tests.conftest import free_port, stb_process, wait_for


def write_lab(tmp_path: Path, router_endpoint: str, crater_file: Path) -> tuple[Path, dict]:
    ports = {"mocap": free_port(), "crane": free_port(), "ptz1": free_port(),
             "ptz2": free_port(), "observation": free_port()}
    lab = tmp_path / "lab.toml"
    lab.write_text(f"""
[bus.zenoh]
connect = ["{router_endpoint}"]
[tracker]
qtm_port = {ports["mocap"]}
[calib]
data_dir = "{tmp_path / 'calib'}"
[gantry]
crane_port = {ports["crane"]}
height_map = "{crater_file}"
[ptz.cameras.ptz1]
url = "http://127.0.0.1:{ports["ptz1"]}"
[ptz.cameras.ptz2]
url = "http://127.0.0.1:{ports["ptz2"]}"
[observation]
url = "http://127.0.0.1:{ports["observation"]}"
[sim]
crater_file = "{crater_file}"
[sim.mocap]
port = {ports["mocap"]}
[sim.crane]
port = {ports["crane"]}
[sim.observation_camera]
port = {ports["observation"]}
[[sim.cameras]]
name = "ptz1"
port = {ports["ptz1"]}
x_mm = 3550
y_mm = 1090
z_mm = 2190
rx_deg = 180
ry_deg = 30
rz_deg = 165
[[sim.cameras]]
name = "ptz2"
port = {ports["ptz2"]}
x_mm = -3300
y_mm = -1800
z_mm = 2600
rx_deg = 164
ry_deg = -27
rz_deg = -33
""")
    return lab, ports


@pytest.fixture
def sim(tmp_path: Path, router_endpoint: str, crater_file: Path) -> Iterator[dict]:
    lab, ports = write_lab(tmp_path, router_endpoint, crater_file)
    proc = stb_process("sim", "--lab", str(lab))
    yield {"proc": proc, "ports": ports, "lab": lab}
    if proc.poll() is None:
        proc.kill()
        proc.wait()


def test_sim_serves_every_device_and_publishes(sim: dict, make_bus: Callable[..., Bus]) -> None:
    bus = make_bus()
    frames: list[m.CameraFrame] = []
    robots: list[m.RobotTruth] = []
    cranes: list[m.CraneTruth] = []
    bus.subscribe(keys.GANTRY_FRAME, frames.append)
    bus.subscribe(keys.TRUTH_ROBOT, robots.append, latest=False)
    bus.subscribe(keys.TRUTH_CRANE, cranes.append, latest=False)
    wait_for(lambda: len(frames) > 5 and len(robots) > 5 and cranes, timeout=20)
    frame = frames[-1]
    image = np.frombuffer(frame.data, np.uint8).reshape(frame.height_px, frame.width_px)
    assert image.max() > 200, "the robot's marker is in the tracking camera's view"
    assert abs(time.time() - frame.measured_s) < 1.0
    assert robots[-1].robot == "locomotive"

    ports = sim["ports"]
    reply = httpx.get(f"http://127.0.0.1:{ports['ptz1']}/axis-cgi/com/ptz.cgi?query=position",
                      auth=httpx.DigestAuth("root", "pass"), timeout=3)
    assert reply.status_code == 200 and "pan=" in reply.text

    crane = ModbusTcpClient("127.0.0.1", port=ports["crane"], timeout=3)
    assert crane.connect()
    try:
        assert not crane.read_input_registers(0, count=16).isError()
    finally:
        crane.close()

    async def mocap() -> Any:  # qtm-rt's packet (the library has no types)
        conn = await qtm_rt.connect("127.0.0.1", port=ports["mocap"], version="1.25")
        try:
            return await conn.get_current_frame(components=["3d"])
        finally:
            conn.disconnect()

    packet = asyncio.run(mocap())
    _, markers = packet.get_3d_markers()
    assert len(markers) == 11, ("robot, wand (absent: NaN), three static markers, the crane's "
                                "and the bodies' other markers (robot's three, wand's two)")
    crane_marker = markers[5]  # after the static ones: on the carriage, at the lens's height
    assert abs(crane_marker.z - 3500.0) < 5.0

    proc = sim["proc"]
    proc.send_signal(signal.SIGINT)
    assert proc.wait(10) == 0


def test_a_port_in_use_is_a_clear_start_up_error(tmp_path: Path, router_endpoint: str,
                                                 crater_file: Path) -> None:
    import socket

    lab, ports = write_lab(tmp_path, router_endpoint, crater_file)
    with socket.create_server(("127.0.0.1", ports["mocap"])):
        proc = stb_process("sim", "--lab", str(lab))
        assert proc.wait(20) == 4
    err = proc.stderr.read()
    assert f"QTM RT: cannot listen on 127.0.0.1:{ports['mocap']}" in err
