"""The QTM RT server, driven by the unmodified qtm-rt client over TCP."""

from __future__ import annotations

import asyncio
import struct
import time
from collections.abc import Awaitable, Callable
from typing import Any, TypeVar

import numpy as np
import pytest
import qtm_rt

from services.sim.lab import Lab
from services.sim.mocap_server import MocapServer, MocapSource
from tests.conftest import poll_async
from tests.simlab import sim_settings

T = TypeVar("T")


def _run(lab: Lab, client: Callable[[int], Awaitable[T]], *, capturing: bool = True,
         rate_hz: float | None = None, start_s: float = 0.0) -> T:
    """Serve ``lab`` (its capture at ``start_s`` now) to ``client(port)``."""
    rate = rate_hz or lab.settings.mocap.rate_hz
    t0 = time.monotonic() - start_s
    source = MocapSource(lab.labels, rate, lab.mocap_frame, lambda: time.monotonic() - t0,
                         lab.body_points)

    async def main() -> T:
        server = MocapServer(source, "127.0.0.1", 0, capturing=capturing)
        await server.start()
        try:
            return await client(server.port)
        finally:
            await server.close()

    return asyncio.run(main())


async def _packets_until(packets: list, count: int, timeout: float) -> None:
    """Waits on the event loop until the client's callback has put ``count`` packets in
    ``packets``; fails after ``timeout`` s."""
    async def enough() -> bool:
        return len(packets) >= count

    assert await poll_async(enough, timeout), f"{len(packets)} of {count} packets in {timeout} s"


async def _stream(port: int, components: list[str], frames: str = "allframes", *,
                  count: int | None = None, seconds: float | None = None) -> list[Any]:
    """The packets streamed until ``count`` came (at most 30 s), or over ``seconds``: a
    window for a test about the rate, or about nothing coming."""
    conn = await qtm_rt.connect("127.0.0.1", port=port, version="1.25")
    assert conn is not None, "the real client must accept our server"
    packets: list = []
    await conn.stream_frames(frames=frames, components=components, on_packet=packets.append)
    if count is not None:
        await _packets_until(packets, count, timeout=30)
    else:
        assert seconds is not None
        await asyncio.sleep(seconds)  # the window itself is the subject
    await conn.stream_frames_stop()
    conn.disconnect()
    return packets


def test_handshake_labels_and_state(lab: Lab) -> None:
    async def client(port: int) -> tuple[Any, ...]:
        conn = await qtm_rt.connect("127.0.0.1", port=port, version="1.25")
        assert conn is not None
        try:
            return (await conn.qtm_version(), await conn.byte_order(),
                    await conn.get_parameters(["3d"]), await conn.get_state())
        finally:
            conn.disconnect()

    version, order, xml, state = _run(lab, client)
    assert version.startswith(b"QTM Version is") and order == b"Byte order is little endian"
    assert b"<Name>robot</Name>" in xml and b"<Name>static_1</Name>" in xml
    assert b"<AxisUpwards>+Z</AxisUpwards>" in xml
    assert state == qtm_rt.QRTEvent.EventCaptureStarted


def test_streamed_markers_equal_the_truth_within_the_noise(lab: Lab) -> None:
    packets = _run(lab, lambda port: _stream(port, ["3d", "3dnolabels"], count=150))
    numbers = [p.framenumber for p in packets]
    assert numbers == sorted(numbers) and len(set(numbers)) == len(numbers)
    errors: list[float] = []
    missing = 0
    for p in packets:
        _, markers = p.get_3d_markers()
        assert len(markers) == len(lab.labels)
        t = p.framenumber / 100.0
        wand = lab.wand_position(t)
        truth = np.vstack([lab.robot(t)[None, :], np.full((1, 3), np.nan) if wand is None
                           else wand[None, :], lab.static_markers])
        for measured, true in zip(markers[:len(truth)], truth, strict=True):  # bodies' below
            xyz = np.array([measured.x, measured.y, measured.z])
            if np.isnan(true).any():
                assert np.isnan(xyz).all(), "the wand is absent while the robot runs"
            elif np.isnan(xyz).any():
                missing += 1
            else:
                errors.append(float(np.linalg.norm(xyz - true)))
        assert abs(p.timestamp - p.framenumber * 10_000) <= 1
    error = np.array(errors)
    assert np.sqrt(np.mean(error**2)) < 1.5, "about 0.5 mm per axis"
    assert error.max() < 5.0
    assert missing < 0.05 * len(packets) * len(lab.labels)


def test_the_server_logs_when_each_frame_left_it(lab: Lab) -> None:
    servers: list[MocapServer] = []

    async def client(port: int) -> tuple[list, float]:
        started = time.time()
        packets = await _stream(port, ["3d"], count=50)
        return packets, started

    t0 = time.monotonic()
    source = MocapSource(lab.labels, 100.0, lab.mocap_frame, lambda: time.monotonic() - t0)

    async def main() -> tuple[list, float]:
        server = MocapServer(source, "127.0.0.1", 0)
        servers.append(server)
        await server.start()
        try:
            return await client(server.port)
        finally:
            await server.close()

    packets, started = asyncio.run(main())
    sent = dict(servers[0].sent)
    received = [p.framenumber for p in packets]
    assert set(received) <= set(sent), "every frame the client got was logged"
    times = [sent[n] for n in received]
    assert times == sorted(times) and started <= times[0] <= time.time()
    wall0 = time.time() - (time.monotonic() - t0)
    late = [sent[n] - (wall0 + n / 100.0) for n in received]
    assert min(late) > -0.002, "no frame leaves before its capture time"


def test_dropouts_are_nan_markers(lab: Lab) -> None:
    frames = [lab.mocap_frame(n) for n in range(3000)]
    wand = [i for i, label in enumerate(lab.labels) if label.startswith("wand")]
    lost = sum(int(np.isnan(np.delete(f.labelled, wand, axis=0)).any()) for f in frames)
    assert 0 < lost < 600
    occluded = [n for n, f in enumerate(frames) if np.isnan(f.labelled[0]).all()]
    assert occluded, "the robot marker is sometimes lost for a while"


def test_rate_and_frequency_divisor(crater_file, crater) -> None:
    lab = Lab.build(sim_settings(crater_file, mocap={"rate_hz": 500, "port": 0}), crater)
    packets = _run(lab, lambda port: _stream(port, ["3d"], "frequencydivisor:5", seconds=1.0))
    gaps = np.diff([p.framenumber for p in packets])
    assert set(gaps) == {5} and 80 <= len(packets) <= 110


def test_unlabelled_robot_marker_comes_in_3dnolabels(crater_file, crater) -> None:
    lab = Lab.build(sim_settings(crater_file, mocap={"robot_label": "", "port": 0}), crater)
    packets = _run(lab, lambda port: _stream(port, ["3dnolabels"], count=50))
    ids = {m.id for p in packets for m in p.get_3d_markers_no_label()[1]}
    assert 1 in ids, "the robot as an unidentified marker with a stable id"


def test_no_more_data_while_not_capturing(lab: Lab) -> None:
    packets = _run(lab, lambda port: _stream(port, ["3d"], seconds=0.5), capturing=False)
    assert packets == []


def test_master_stops_and_starts_the_capture_with_events(lab: Lab) -> None:
    async def client(port: int) -> dict:
        events: list = []
        conn = await qtm_rt.connect("127.0.0.1", port=port, version="1.25",
                                    on_event=events.append)
        watcher = await qtm_rt.connect("127.0.0.1", port=port, version="1.25")
        try:
            with pytest.raises(qtm_rt.QRTCommandException, match="master"):
                await conn.stop()
            await conn.take_control("")
            await conn.stop()
            stopped = await conn.get_state()
            packets: list = []
            # While stopped the stream request is answered with NoMoreData: no frames.
            await watcher.stream_frames(components=["3d"], on_packet=packets.append)
            await asyncio.sleep(0.3)  # a quiet window: nothing may come while stopped
            idle = len(packets)
            await conn.start()
            await _packets_until(packets, idle + 11, timeout=10)
            await watcher.stream_frames_stop()
            return {"events": events, "stopped": stopped, "idle": idle, "running": len(packets)}
        finally:
            conn.disconnect()
            watcher.disconnect()

    out = _run(lab, client)
    assert out["stopped"] == qtm_rt.QRTEvent.EventCaptureStopped
    assert qtm_rt.QRTEvent.EventCaptureStopped in out["events"]
    assert qtm_rt.QRTEvent.EventCaptureStarted in out["events"]
    assert out["idle"] == 0 and out["running"] > 10


def test_unknown_command_is_an_error_reply(lab: Lab) -> None:
    async def client(port: int) -> None:
        conn = await qtm_rt.connect("127.0.0.1", port=port, version="1.25")
        try:
            with pytest.raises(qtm_rt.QRTCommandException):
                await conn.get_current_frame(components=["skeleton"])
            assert (await conn.qtm_version()).startswith(b"QTM"), "connection still usable"
        finally:
            conn.disconnect()

    _run(lab, client)


def test_frames_are_deterministic_under_the_seed(crater_file, crater) -> None:
    a = Lab.build(sim_settings(crater_file, seed=3), crater)
    b = Lab.build(sim_settings(crater_file, seed=3), crater)
    c = Lab.build(sim_settings(crater_file, seed=4), crater)
    for n in (0, 777, 4321):
        fa, fb, fc = a.mocap_frame(n), b.mocap_frame(n), c.mocap_frame(n)
        np.testing.assert_array_equal(fa.labelled, fb.labelled)
        assert not np.array_equal(np.nan_to_num(fa.labelled), np.nan_to_num(fc.labelled))


def test_commands_in_the_sdks_casing_stream_and_stop(lab: Lab) -> None:
    """QTM's commands are case-insensitive: Qualisys' own C++ and C# SDKs send
    ``StreamFrames FrequencyDivisor:2 3D`` and ``StreamFrames Stop``, qtm-rt lower case."""
    header = struct.Struct("<II")

    async def client(port: int) -> tuple[int, int]:
        reader, writer = await asyncio.open_connection("127.0.0.1", port)

        async def packet() -> tuple[int, bytes]:
            size, kind = header.unpack(await reader.readexactly(header.size))
            return kind, await reader.readexactly(size - header.size)

        def command(text: str) -> None:
            body = text.encode() + b"\0"
            writer.write(header.pack(header.size + len(body), 1) + body)

        try:
            assert (await packet())[1].startswith(b"QTM RT Interface connected")
            command("StreamFrames FrequencyDivisor:2 3D")
            kinds = [(await asyncio.wait_for(packet(), 2.0))[0] for _ in range(5)]
            command("StreamFrames Stop")
            command("QTMVersion")
            while (reply := await asyncio.wait_for(packet(), 2.0))[0] == 3:  # data in flight
                pass
            return kinds.count(3), reply[0]
        finally:
            writer.close()

    data_packets, after_stop = _run(lab, client)
    assert data_packets == 5, "StreamFrames in the SDKs' casing streams data packets"
    assert after_stop == 1, "after StreamFrames Stop the next packet is the command's reply"
