"""The motion-capture driver: a small interface and Qualisys QTM over its RT protocol (qtm-rt).

``QualisysMocap.run`` connects, reads the 3D labels (and, when asked for one, the 6DOF bodies),
streams ``3d`` and ``3dnolabels`` (and ``6d``) and hands every frame on as a ``MarkerFrame``;
when QTM goes away it reconnects with backoff. NaN markers and bodies (lost by QTM) are left
out, never sent as zero. QTM sends a body's rotation matrix column by column.
"""

from __future__ import annotations

import asyncio
import logging
import math
import struct
import threading
import time
import xml.etree.ElementTree as ET
from collections.abc import Callable, Iterator, Sequence
from typing import Protocol

import numpy as np
import qtm_rt
from qtm_rt.packet import QRTComponentType

from common import messages as m
from common.backoff import Backoff
from common.camera import quaternion_wxyz
from common.messages import MarkerFrame, RigidBody
from common.qtm_params import bodies_from_xml, labels_from_xml

log = logging.getLogger(__name__)

FrameHandler = Callable[[MarkerFrame], None]
StateHandler = Callable[[bool, str], None]


class MotionCapture(Protocol):
    """A motion-capture system: hands every frame to ``on_frame`` until ``stop`` is set, and
    says on ``on_state`` whether it is connected (and why not). ``QualisysMocap`` is QTM's."""

    def run(self, on_frame: FrameHandler, stop: threading.Event,
            on_state: StateHandler = ...) -> None: ...


class ClockSync:
    """Maps QTM's capture time stamps onto this host's clock. QTM's clock runs on its own:
    the smallest observed (arrival − stamp), the arrival read on the *monotonic* clock, is the
    transport delay floor; it may creep up slowly for the two clocks' drift (``creep_per_s``,
    a crystal's: 100 ppm), never faster — so that a backlog after a stall is not taken for a
    clock change, and its frames keep their age. The wall clock is read at each arrival and
    the result moved onto it: a host whose wall clock is stepped or slewed (NTP, chrony; seen
    on a CI machine: a step of ≈ 5 s forward, then 2 000–5 000 ppm against its monotonic
    clock for minutes) would otherwise make every frame look seconds old."""

    def __init__(self, creep_per_s: float = 1e-4) -> None:
        self._offset: float | None = None
        self._last: float | None = None
        self._creep = creep_per_s

    def measured(self, stamp_s: float, arrived_monotonic_s: float, wall_now_s: float) -> float:
        """The wall time at which the frame stamped ``stamp_s`` (QTM's clock) was captured,
        for a frame that arrived at ``arrived_monotonic_s`` when the wall clock read
        ``wall_now_s``."""
        sample = arrived_monotonic_s - stamp_s
        if self._offset is None or self._last is None:
            self._offset = sample
        else:
            self._offset = min(self._offset + self._creep * (arrived_monotonic_s - self._last),
                               sample)
        self._last = arrived_monotonic_s
        return stamp_s + self._offset + (wall_now_s - arrived_monotonic_s)


# a 3D component: its header (marker count, 2D drop rate, out-of-sync rate), then per marker
# x, y, z (float32) — and, without labels, an id (int32); QTM RT protocol, little endian
_3D_HEADER = struct.Struct("<Ihh")
_XYZ = struct.Struct("<3f")
_XYZ_ID = struct.Struct("<3fi")


def _component(packet: qtm_rt.QRTPacket, kind: QRTComponentType, marker: struct.Struct
               ) -> Iterator[tuple]:
    """A 3D component's markers, unpacked in one go (at QTM's full rate, qtm-rt's one named
    tuple at a time was the tracker's largest cost); none when the packet has no such part."""
    position = packet.components.get(kind)
    if position is None:
        return iter(())
    count = _3D_HEADER.unpack_from(packet.data, position)[0]
    start = position + _3D_HEADER.size
    return marker.iter_unpack(memoryview(packet.data)[start:start + count * marker.size])


def frame_from_packet(packet: qtm_rt.QRTPacket, labels: list[str], measured_s: float,
                      body_names: Sequence[str] = ()) -> MarkerFrame:
    """A MarkerFrame from a QTM data packet; lost (NaN) markers and bodies are left out."""
    finite = math.isfinite
    markers = [{"label": label, "x_mm": x, "y_mm": y, "z_mm": z}
               for label, (x, y, z) in zip(labels, _component(
                   packet, QRTComponentType.Component3d, _XYZ), strict=False)
               if finite(x) and finite(y) and finite(z)]
    markers += [{"id": marker_id, "x_mm": x, "y_mm": y, "z_mm": z}
                for x, y, z, marker_id in _component(
                    packet, QRTComponentType.Component3dNoLabels, _XYZ_ID)
                if marker_id >= 0 and finite(x) and finite(y) and finite(z)]
    # validated in one call (a Marker made one at a time cost twice as much)
    return MarkerFrame.model_validate({
        "measured_s": measured_s, "frame": packet.framenumber, "markers": markers[:1000],
        "bodies": _bodies(packet, body_names) if body_names else []})


def _bodies(packet: qtm_rt.QRTPacket, names: Sequence[str]) -> list[RigidBody]:
    six_d = packet.get_6d()
    if six_d is None:
        return []
    bodies = []
    for name, (position, rotation) in zip(names, six_d[1], strict=False):
        values = (position.x, position.y, position.z, *rotation.matrix)
        if not name or not all(math.isfinite(v) for v in values):
            continue
        matrix = np.array(rotation.matrix, dtype=float).reshape(3, 3).T  # column by column
        qw, qx, qy, qz = quaternion_wxyz(matrix)
        bodies.append(RigidBody(name=m.name(name), x_mm=position.x, y_mm=position.y,
                                z_mm=position.z, qw=qw, qx=qx, qy=qy, qz=qz))
    return bodies[:100]


class QualisysMocap:
    def __init__(self, host: str = "127.0.0.1", port: int = 22223, *,
                 frames: str = "allframes", timeout_s: float = 5.0,
                 retry_initial_s: float = 0.5, retry_max_s: float = 5.0,
                 clock: Callable[[], float] = time.time,
                 monotonic: Callable[[], float] = time.monotonic, body: str = "") -> None:
        """``body``: a 6DOF body to stream (and check QTM has); "" = markers only."""
        self.host, self.port, self.frames, self.body = host, port, frames, body
        self.timeout_s, self.retry_initial_s, self.retry_max_s = (timeout_s, retry_initial_s,
                                                                  retry_max_s)
        self.clock, self.monotonic = clock, monotonic

    def run(self, on_frame: FrameHandler, stop: threading.Event,
            on_state: StateHandler = lambda connected, why: None) -> None:
        """Stream until ``stop`` is set, reconnecting whenever QTM goes away."""
        asyncio.run(self._main(on_frame, stop, on_state))

    async def _main(self, on_frame: FrameHandler, stop: threading.Event,
                    on_state: StateHandler) -> None:
        backoff = Backoff(self.retry_initial_s, self.retry_max_s)
        while not stop.is_set():
            lost = asyncio.Event()
            conn = await qtm_rt.connect(self.host, port=self.port, version="1.25",
                                        on_disconnect=lambda _exc, lost=lost: lost.set(),
                                        timeout=self.timeout_s)
            if conn is None:
                on_state(False, f"QTM at {self.host}:{self.port} does not answer")
                await _wait(stop, backoff.failed())
                continue
            try:
                await self._stream(conn, on_frame, stop, lost, on_state)
                backoff.succeeded()
            except (TimeoutError, qtm_rt.QRTCommandException, ET.ParseError) as err:
                on_state(False, f"QTM at {self.host}:{self.port}: {err}")
                await _wait(stop, backoff.failed())
            finally:
                if conn.has_transport():  # qtm-rt's disconnect() fails once QTM has gone
                    conn.disconnect()

    async def _stream(self, conn: qtm_rt.QRTConnection, on_frame: FrameHandler,
                      stop: threading.Event, lost: asyncio.Event,
                      on_state: StateHandler) -> None:
        labels = labels_from_xml(await conn.get_parameters(parameters=["3d"]))
        bodies = bodies_from_xml(await conn.get_parameters(parameters=["6d"])) if self.body \
            else []
        sync = ClockSync()

        def on_packet(packet: qtm_rt.QRTPacket) -> None:
            measured = sync.measured(packet.timestamp / 1e6, self.monotonic(), self.clock())
            on_frame(frame_from_packet(packet, labels, measured, bodies))

        components = ["3d", "3dnolabels", *(["6d"] if self.body else [])]
        await conn.stream_frames(frames=self.frames, components=components, on_packet=on_packet)
        if self.body and self.body not in bodies:
            on_state(False, f"QTM at {self.host}:{self.port} has no 6DOF body {self.body!r} "
                     f"(it has: {', '.join(bodies) or 'none'})")
        else:
            on_state(True, f"streaming from QTM at {self.host}:{self.port} ({len(labels)} "
                     f"labels, {len(bodies)} bodies)")
        while not stop.is_set() and not lost.is_set():
            await asyncio.sleep(0.05)
        if lost.is_set():
            on_state(False, f"QTM at {self.host}:{self.port} went away")
        else:
            await conn.stream_frames_stop()


async def _wait(stop: threading.Event, seconds: float) -> None:
    end = time.monotonic() + seconds
    while not stop.is_set() and time.monotonic() < end:
        await asyncio.sleep(0.05)
