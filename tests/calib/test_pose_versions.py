"""The calibration service owns its pose keys: every solve is a new version, and a pose on its
key that it did not send is answered with its own at a higher version (loopback bus)."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

from common import keys
from common import messages as m
from common.bus import Bus
from common.node import Node
from services.calib.service import Calib
from services.calib.settings import CalibSettings
from services.calib.store import PoseStore
from tests.conftest import wait_for

SOLVED = dict(camera="ptz1", x_mm=3550.0, y_mm=1090.0, z_mm=2190.0, rx_deg=180.0, ry_deg=30.0,
              rz_deg=165.0, focal_mm=3.8, mean_error_px=1.2, passpoints=100)


def _service(make_bus: Callable[..., Bus], data_dir: Path) -> tuple[Calib, Node]:
    settings = CalibSettings(cameras=["ptz1"], data_dir=data_dir)
    node = Node("calib", settings, make_bus())
    calib = Calib(node, settings, PoseStore(data_dir))
    calib.start()
    return calib, node


def test_a_foreign_pose_is_out_versioned_stored_and_reported(make_bus: Callable[..., Bus],
                                                               tmp_path: Path) -> None:
    store = PoseStore(tmp_path)
    store.save(m.CameraPose(measured_s=time.time() - 60, version=2, **SOLVED), {"method": "x"})
    world = make_bus()
    heard: list[m.CameraPose] = []
    world.subscribe(keys.CALIB_POSE, heard.append, latest=False, camera="ptz1")
    calib, node = _service(make_bus, tmp_path)
    time.sleep(0.5)
    assert [p.version for p in heard] == [2], "its stored pose, once: its own echo is no news"
    assert node.health().status == "ok"

    spoof = m.CameraPose(measured_s=time.time(), version=7, **{**SOLVED, "rz_deg": 100.0})
    world.publish(keys.CALIB_POSE, spoof, camera="ptz1")
    wait_for(lambda: heard[-1].version == 8, timeout=3)
    answer = heard[-1]
    assert (answer.rz_deg, answer.measured_s) == (165.0, heard[0].measured_s), "its own solve"
    assert store.load("ptz1").version == 8, "a restart publishes the version that won"
    health = node.health()
    assert health.status == "degraded" and "ptz1: a pose it did not send" in health.detail

    start = len(heard)
    began = time.monotonic()
    for _ in range(300):  # a flood: answered at most five times a second
        world.publish(keys.CALIB_POSE, spoof.model_copy(update={"version": 9}), camera="ptz1")
        time.sleep(0.005)
    time.sleep(0.5)
    answers = [p for p in heard[start:] if p.rz_deg == 165.0]
    elapsed = time.monotonic() - began
    assert 1 <= len(answers) <= elapsed / 0.2 + 2, (len(answers), elapsed)
    assert answers[-1].version == 10
    assert calib.foreign["ptz1"] and len(calib.foreign["ptz1"]) == 301, "every one counted"

    assert all(p.version == 9 for p in heard[start:] if p.rz_deg != 165.0)
    assert store.load("ptz1").version == 10
    before = len(heard)
    world.publish(keys.CALIB_POSE, spoof.model_copy(update={"version": 3}), camera="ptz1")
    time.sleep(0.5)  # a lower version: no PTZ service takes it, no answer needed
    assert [p.version for p in heard[before:]] == [3]
    node.stop.set()


def test_a_solve_outruns_every_version_heard(make_bus: Callable[..., Bus],
                                             tmp_path: Path) -> None:
    """A fresh data folder (no stored pose) after poses up to version 5 were on the bus: its
    first solve is version 6, so that PTZ services holding version 5 take it."""
    world = make_bus()
    heard: list[m.CameraPose] = []
    world.subscribe(keys.CALIB_POSE, heard.append, latest=False, camera="ptz1")
    calib, node = _service(make_bus, tmp_path)
    time.sleep(0.3)
    world.publish(keys.CALIB_POSE, m.CameraPose(measured_s=time.time(), version=5, **SOLVED),
                  camera="ptz1")
    wait_for(lambda: len(heard) == 1 and calib.seen_version.get("ptz1") == 5)  # both heard it
    calib.solved(m.CameraPose(measured_s=time.time(), **SOLVED), {"method": "test"})
    wait_for(lambda: len(heard) == 2)
    assert heard[-1].version == 6 and PoseStore(tmp_path).load("ptz1").version == 6
    assert node.health().status == "ok", "a pose heard while it had none is not foreign"
    node.stop.set()
