"""The tracker's floor: what receiving QTM's stream and making the tracker's two Zenoh puts a
frame costs in Python, and what each part of the tracker's own work adds to it — without the
message models. ``python -m benchmarks.tracker --floor LEVEL`` runs it in the tracker's place:

    python -m benchmarks.tracker_floor --qtm-port P --connect tcp/127.0.0.1:R [--level L]

It connects to QTM with qtm-rt on asyncio as the tracker does (``services.tracker.mocap``),
streams the same components, and for every packet makes two puts on ``stb/tracker/robot`` and
``stb/tracker/markers`` — the same session settings, publishers and congestion control as the
bus's. What it puts, by ``--level``:

* ``receive``: a robot message packed once, and the packet's bytes (about the size of the
  marker frame the tracker packs); nothing else is done.
* ``read``: every finite marker read from the packet as the tracker reads it, the frame packed
  in the cheapest form there is — the labels, the ids and the positions as one float32 array
  (not our wire format: no model, no map per marker) — and a robot message at a fixed place,
  packed with the frame's time stamps.
* ``pick``: the same, and the robot found among the labelled markers by the tracker's own
  picker (``common.robot_picker``), its position and velocity in the robot message.
"""

from __future__ import annotations

import argparse
import asyncio
import math
import struct
import time
from collections.abc import Callable

import msgpack
import qtm_rt
import zenoh
from qtm_rt.packet import QRTComponentType

from common import codec, keys
from common import messages as m
from common.bus import declare_publisher, open_session
from common.qtm_params import labels_from_xml
from common.robot_picker import RobotPicker, Seen
from common.settings import ZenohSettings
from services.args import Parser
from services.tracker.mocap import _XYZ, _XYZ_ID, ClockSync, _component

LEVELS = ("receive", "read", "pick")


def _handler(level: str, publishers: list[zenoh.Publisher], labels: list[str]
             ) -> Callable[[qtm_rt.QRTPacket], None]:
    robot = codec.encode(m.RobotPosition(measured_s=time.time(), label="robot", x_mm=1.0,
                                         y_mm=2.0, z_mm=3.0, vx_mm_s=0.0, vy_mm_s=0.0,
                                         vz_mm_s=0.0), sent_s=time.time())
    if level == "receive":
        def receive(packet: qtm_rt.QRTPacket) -> None:
            publishers[0].put(robot)
            publishers[1].put(bytes(packet.data))
        return receive

    picker, sync, finite = RobotPicker("robot"), ClockSync(), math.isfinite
    fixed = ((1.0, 2.0, 3.0), (0.0, 0.0, 0.0))

    def read(packet: qtm_rt.QRTPacket) -> None:
        measured = sync.measured(packet.timestamp / 1e6, time.monotonic(), time.time())
        named = [(label, x, y, z) for label, (x, y, z) in zip(labels, _component(
            packet, QRTComponentType.Component3d, _XYZ), strict=False)
            if finite(x) and finite(y) and finite(z)]
        unnamed = [(marker_id, x, y, z) for x, y, z, marker_id in _component(
            packet, QRTComponentType.Component3dNoLabels, _XYZ_ID)
            if marker_id >= 0 and finite(x) and finite(y) and finite(z)]
        found = picker.update(measured, [Seen(name, 0, x, y, z) for name, x, y, z in named]) \
            if level == "pick" else fixed
        sent = time.time()
        if found is not None:
            (x, y, z), (vx, vy, vz) = found
            publishers[0].put(msgpack.packb({
                "measured_s": measured, "sent_s": sent, "label": "robot", "x_mm": float(x),
                "y_mm": float(y), "z_mm": float(z), "vx_mm_s": float(vx), "vy_mm_s": float(vy),
                "vz_mm_s": float(vz)}))
        xyz = [c for row in named for c in row[1:]] + [c for row in unnamed for c in row[1:]]
        publishers[1].put(msgpack.packb({
            "measured_s": measured, "sent_s": sent, "frame": packet.framenumber,
            "labels": [row[0] for row in named], "ids": [row[0] for row in unnamed],
            "xyz_mm": struct.pack(f"<{len(xyz)}f", *xyz)}))
    return read


async def _stream(port: int, session: zenoh.Session, seconds: float, level: str) -> None:
    publishers = [declare_publisher(session, topic.key(keys.DEFAULT_PREFIX), topic.model)
                  for topic in (keys.TRACKER_ROBOT, keys.TRACKER_MARKERS)]

    deadline = time.monotonic() + 60
    while True:  # as the tracker: until the sim's QTM streams (it may still be starting)
        conn = await qtm_rt.connect("127.0.0.1", port=port, version="1.25", timeout=5)
        try:
            if conn is not None:
                labels = labels_from_xml(await conn.get_parameters(parameters=["3d"]))
                await conn.stream_frames(frames="allframes", components=["3d", "3dnolabels"],
                                         on_packet=_handler(level, publishers, labels))
                break
        except TimeoutError:
            conn.disconnect()
        if time.monotonic() > deadline:
            raise SystemExit(f"QTM at 127.0.0.1:{port} does not stream")
        await asyncio.sleep(0.5)
    await asyncio.sleep(seconds)


def main() -> None:
    parser = Parser(description=__doc__,
                    formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--qtm-port", type=int, required=True)
    parser.add_argument("--connect", required=True, help="the router's endpoint")
    parser.add_argument("--seconds", type=float, default=3600.0)
    parser.add_argument("--level", choices=LEVELS, default="receive")
    args = parser.parse_args()
    session = open_session(ZenohSettings(connect=[args.connect]))
    try:
        asyncio.run(_stream(args.qtm_port, session, args.seconds, args.level))
    finally:
        session.close()


if __name__ == "__main__":
    main()
