"""The tracker's floor benchmark reads what the tracker reads: its cheaper frame must hold the
same markers, or its figures would undercount the work they stand for."""

from __future__ import annotations

import struct

import msgpack
import numpy as np
import pytest
import qtm_rt

from benchmarks.tracker_floor import _handler
from services.sim.mocap_server import COMPONENT_3D, COMPONENT_3D_NO_LABELS, MocapFrame, data_packet
from services.tracker.mocap import frame_from_packet


class _Puts:
    """Where the floor's two publishers put (a list each)."""

    def __init__(self) -> None:
        self.payloads: list[bytes] = []

    def put(self, payload: bytes) -> None:
        self.payloads.append(payload)


def _packet(number: int, robot_x: float) -> qtm_rt.QRTPacket:
    rng = np.random.default_rng(number)
    labelled = rng.uniform(-3000, 3000, (4, 3))
    labelled[0] = (robot_x, 100.0, 50.0)  # "robot" first
    labelled[2] = np.nan  # lost by QTM
    unlabelled = [(100, rng.uniform(-3000, 3000, 3)), (-1, rng.uniform(-3000, 3000, 3)),
                  (101, rng.uniform(-3000, 3000, 3))]
    raw = data_packet(MocapFrame(number, number * 1000, labelled, unlabelled),
                      {COMPONENT_3D, COMPONENT_3D_NO_LABELS})
    return qtm_rt.QRTPacket(raw[8:])


@pytest.mark.parametrize("level", ["read", "pick"])
def test_the_floors_packed_frame_holds_the_trackers_markers(level: str) -> None:
    labels = ["robot", "a", "b", "c"]
    robot, markers = _Puts(), _Puts()
    handle = _handler(level, [robot, markers], labels)  # type: ignore[list-item]
    packets = [_packet(n, robot_x=10.0 * n) for n in range(1, 41)]
    for packet in packets:
        handle(packet)

    assert len(markers.payloads) == len(packets)
    for packet, payload in zip(packets, markers.payloads, strict=True):
        ours = frame_from_packet(packet, labels, measured_s=0.0).markers
        packed = msgpack.unpackb(payload)
        xyz = np.array(struct.unpack(f"<{len(packed['xyz_mm']) // 4}f", packed["xyz_mm"]))
        assert packed["frame"] == packet.framenumber
        assert packed["labels"] == [mk.label for mk in ours if mk.label]
        assert packed["ids"] == [mk.id for mk in ours if not mk.label]
        assert xyz.reshape(-1, 3) == pytest.approx(
            np.array([(mk.x_mm, mk.y_mm, mk.z_mm) for mk in ours]))
    last = msgpack.unpackb(robot.payloads[-1])
    if level == "pick":  # the picker's robot: the labelled marker, moving 10 mm a frame
        assert last["x_mm"] == pytest.approx(400.0)
        assert last["vx_mm_s"] > 0
    else:
        assert last["x_mm"] == 1.0
