"""The calibration service's stored pose is the truth: a pose on its key that it did not send
— at any version, 2⁵³ included — changes nothing it stores, publishes or answers; it is
counted and reported. Its versions count its own solves (loopback bus)."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import zenoh

from common import codec, keys
from common import messages as m
from common.bus import Bus
from common.node import Node
from services.calib.service import Calib
from services.calib.settings import CalibSettings
from services.calib.store import PoseStore
from tests.conftest import wait_for

SOLVED: dict[str, Any] = dict(
    camera="ptz1", x_mm=3550.0, y_mm=1090.0, z_mm=2190.0, rx_deg=180.0, ry_deg=30.0,
    rz_deg=165.0, focal_px=743.1, mean_error_px=1.2, passpoints=100)


def _service(make_bus: Callable[..., Bus], data_dir: Path) -> tuple[Calib, Node]:
    settings = CalibSettings(cameras=["ptz1"], data_dir=data_dir)
    node = Node("calib", settings, make_bus())
    calib = Calib(node, settings, PoseStore(data_dir))
    calib.start()
    return calib, node


@pytest.mark.parametrize("version", [2**53, 2**53 - 1, 7])
def test_a_foreign_pose_changes_nothing_and_is_reported(make_bus: Callable[..., Bus],
                                                        tmp_path: Path, version: int) -> None:
    store = PoseStore(tmp_path)
    store.save(m.CameraPose(measured_s=time.time() - 60, version=2, **SOLVED), {"method": "x"})
    world = make_bus()
    calib, node = _service(make_bus, tmp_path)
    wait_for(lambda: world.query_latest(keys.CALIB_POSE, timeout_s=0.5, camera="ptz1"))
    assert node.health().status == "ok"
    heard: list[m.CameraPose] = []
    world.subscribe(keys.CALIB_POSE, heard.append, latest=False, camera="ptz1")
    spoof = m.CameraPose(measured_s=time.time(), version=version, **{**SOLVED, "rz_deg": 100.0})
    key = keys.CALIB_POSE.key(world.prefix, camera="ptz1")
    for _ in range(300):  # a flood, each put waiting for room (the bus's own publish drops
        # when Zenoh's queue is full: on a busy machine some of 300 at once did not go out)
        world.session.put(key, codec.encode(spoof, sent_s=time.time()),
                          congestion_control=zenoh.CongestionControl.BLOCK)
    wait_for(lambda: calib.foreign.counts(time.monotonic()).get("ptz1") == 300, timeout=5)
    health = node.health()
    assert health.status == "degraded" and "ptz1: 300 poses it did not send" in health.detail
    assert all(p.rz_deg == 100.0 for p in heard), "it published nothing in answer"
    [answer] = world.query_latest(keys.CALIB_POSE, timeout_s=1.0, camera="ptz1")
    assert (answer.rz_deg, answer.version) == (165.0, 2), "its queryable: its own pose"
    stored = store.load("ptz1")
    assert stored is not None and (stored.rz_deg, stored.version) == (165.0, 2)
    node.stop.set()


def test_its_solves_count_from_its_own_version(make_bus: Callable[..., Bus],
                                               tmp_path: Path) -> None:
    """A fresh data folder after poses up to version 2⁵³ were on the bus: its first solve is
    version 1 — a PTZ service takes the calibration service's answer, not the highest."""
    world = make_bus()
    heard: list[m.CameraPose] = []
    world.subscribe(keys.CALIB_POSE, heard.append, latest=False, camera="ptz1")
    calib, node = _service(make_bus, tmp_path)
    world.publish(keys.CALIB_POSE, m.CameraPose(measured_s=time.time(), version=2**53,
                                                **SOLVED), camera="ptz1")
    wait_for(lambda: heard)
    calib.solved(m.CameraPose(measured_s=time.time(), **SOLVED), {"method": "test"})
    wait_for(lambda: len(heard) == 2)
    stored = PoseStore(tmp_path).load("ptz1")
    assert heard[-1].version == 1 and stored is not None and stored.version == 1
    calib.solved(m.CameraPose(measured_s=time.time(), **SOLVED), {"method": "test"})
    wait_for(lambda: len(heard) == 3)
    assert heard[-1].version == 2
    node.stop.set()
