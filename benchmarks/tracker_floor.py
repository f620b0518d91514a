"""The tracker's floor: what receiving QTM's stream and making the tracker's two Zenoh puts a
frame costs in Python, with none of the tracker's own work (no parsing of the markers, no
model, no picker, no packing). ``python -m benchmarks.tracker --floor`` runs it in the
tracker's place:

    python -m benchmarks.tracker_floor --qtm-port P --connect tcp/127.0.0.1:R

It connects to QTM with qtm-rt on asyncio as the tracker does (``services.tracker.mocap``),
streams the same components, and for every packet puts on ``stb/tracker/markers`` the
packet's bytes (about the size of the marker frame the tracker packs) and on
``stb/tracker/robot`` a robot message packed once — the same session settings, publishers and
congestion control as the bus's.
"""

from __future__ import annotations

import argparse
import asyncio
import time

import qtm_rt
import zenoh

from common import codec, keys
from common import messages as m
from common.bus import declare_publisher, open_session
from common.settings import ZenohSettings


async def _stream(port: int, session: zenoh.Session, seconds: float) -> None:
    publishers = [declare_publisher(session, topic.key(keys.DEFAULT_PREFIX), topic.model)
                  for topic in (keys.TRACKER_ROBOT, keys.TRACKER_MARKERS)]
    robot = codec.encode(m.RobotPosition(measured_s=time.time(), label="robot", x_mm=1.0,
                                         y_mm=2.0, z_mm=3.0, vx_mm_s=0.0, vy_mm_s=0.0,
                                         vz_mm_s=0.0), sent_s=time.time())

    def on_packet(packet: qtm_rt.QRTPacket) -> None:
        publishers[0].put(robot)
        publishers[1].put(bytes(packet.data))

    deadline = time.monotonic() + 60
    while True:  # as the tracker: until the sim's QTM streams (it may still be starting)
        conn = await qtm_rt.connect("127.0.0.1", port=port, version="1.25", timeout=5)
        try:
            if conn is not None:
                await conn.get_parameters(parameters=["3d"])  # as the tracker does
                await conn.stream_frames(frames="allframes", components=["3d", "3dnolabels"],
                                         on_packet=on_packet)
                break
        except TimeoutError:
            conn.disconnect()
        if time.monotonic() > deadline:
            raise SystemExit(f"QTM at 127.0.0.1:{port} does not stream")
        await asyncio.sleep(0.5)
    await asyncio.sleep(seconds)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--qtm-port", type=int, required=True)
    parser.add_argument("--connect", required=True, help="the router's endpoint")
    parser.add_argument("--seconds", type=float, default=3600.0)
    args = parser.parse_args()
    session = open_session(ZenohSettings(connect=[args.connect]))
    try:
        asyncio.run(_stream(args.qtm_port, session, args.seconds))
    finally:
        session.close()


if __name__ == "__main__":
    main()
