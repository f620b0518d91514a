"""The tracker reads QTM's 3D components in one go; what it reads must be what qtm-rt reads."""

from __future__ import annotations

import math

import numpy as np
import qtm_rt

from services.sim.mocap_server import COMPONENT_3D, COMPONENT_3D_NO_LABELS, MocapFrame, data_packet
from services.tracker.mocap import frame_from_packet


def _qtm_rt_markers(packet: qtm_rt.QRTPacket, labels: list[str]) -> list[tuple]:
    """The markers as qtm-rt's own getters give them, lost ones (NaN, id < 0) left out."""
    out = []
    for label, m in zip(labels, packet.get_3d_markers()[1], strict=False):
        if all(math.isfinite(c) for c in (m.x, m.y, m.z)):
            out.append((label, 0, m.x, m.y, m.z))
    for m in packet.get_3d_markers_no_label()[1]:
        if all(math.isfinite(c) for c in (m.x, m.y, m.z)) and m.id >= 0:
            out.append(("", m.id, m.x, m.y, m.z))
    return out


def test_the_markers_read_in_one_go_are_qtm_rts_with_the_lost_ones_left_out() -> None:
    rng = np.random.default_rng(3)
    labelled = rng.uniform(-4000, 4000, (7, 3))
    labelled[[1, 4]] = np.nan  # lost by QTM
    unlabelled = [(100, rng.uniform(-4000, 4000, 3)), (-1, rng.uniform(-4000, 4000, 3)),
                  (7, np.array([np.nan, 1.0, 2.0])), (101, rng.uniform(-4000, 4000, 3))]
    frame = MocapFrame(42, 1_234_567, labelled, unlabelled)
    raw = data_packet(frame, {COMPONENT_3D, COMPONENT_3D_NO_LABELS})
    packet = qtm_rt.QRTPacket(raw[8:])  # after the RT header (size, type)
    labels = [f"m{i}" for i in range(6)]  # one label fewer than markers: the last is unnamed

    ours = frame_from_packet(packet, labels, measured_s=5.0)

    assert ours.frame == 42
    assert [(mk.label, mk.id, mk.x_mm, mk.y_mm, mk.z_mm) for mk in ours.markers] == \
        _qtm_rt_markers(packet, labels)
    assert [mk.id for mk in ours.markers if not mk.label] == [100, 101]
    assert len(ours.markers) == 4 + 2


def test_a_packet_without_3d_components_has_no_markers() -> None:
    frame = MocapFrame(1, 0, np.zeros((0, 3)), [])
    packet = qtm_rt.QRTPacket(data_packet(frame, set())[8:])
    assert frame_from_packet(packet, [], measured_s=0.0).markers == []


def test_a_label_longer_than_a_message_allows_is_cut_not_a_failure_per_frame() -> None:
    from common.qtm_params import labels_from_xml
    long = "x" * 80
    xml = f"<QTM_Parameters_Ver_1.25><The_3D><Label><Name>{long}</Name></Label>" \
          "</The_3D></QTM_Parameters_Ver_1.25>"
    labels = labels_from_xml(xml)
    assert labels == ["x" * 64]
    frame = MocapFrame(1, 0, np.array([[1.0, 2.0, 3.0]]), [])
    packet = qtm_rt.QRTPacket(data_packet(frame, {COMPONENT_3D})[8:])
    assert frame_from_packet(packet, labels, measured_s=0.0).markers[0].label == "x" * 64
