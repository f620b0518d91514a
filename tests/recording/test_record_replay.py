"""Recording and replay over a real loopback bus: what goes in comes back, in order."""

from __future__ import annotations

import io
import json
import time
from collections.abc import Callable
from pathlib import Path

import av
import numpy as np
import pytest
import zenoh
from mcap.reader import make_reader

from common import codec, keys
from common import messages as m
from common.bus import Bus
from common.mcap_file import RecordingError, read_samples, recorded_keys
from common.wiredoc import example
from services.recording.record import Recorder
from services.recording.replay import pace, replay, retimed
from services.recording.typed import LabScene
from services.sim.render import Blob, draw
from tests.conftest import publish_paced, stb_process, until_heard, wait_for
from tests.recording.typed import decoded_typed

ROBOT = "stb/tracker/robot"


def _robot(i: int, t: float) -> m.RobotPosition:
    return m.RobotPosition(measured_s=t, label="robot", x_mm=float(i), y_mm=2.0 * i, z_mm=0.0,
                           vx_mm_s=1.0, vy_mm_s=0.0, vz_mm_s=0.0)


def _frame(t: float) -> m.CameraFrame:
    pixels = np.random.default_rng(0).integers(0, 255, (48, 64), dtype=np.uint8)
    return m.CameraFrame(measured_s=t, camera="tracking", seq=1, width_px=64, height_px=48,
                         encoding="mono8", data=pixels.tobytes())


def _record(bus: Bus, path: Path, publish: Callable[[], object], expect: int,
            heard: tuple[Bus, str], **kw: object) -> Recorder:
    """A recording of what ``publish`` sends, once ``heard``'s bus knows that the recorder
    subscribes to its key."""
    with open(path, "wb") as out:
        recorder = Recorder(bus.session, "stb", ["stb/**"], out, **kw)  # type: ignore[arg-type]
        until_heard(*heard)
        publish()
        wait_for(lambda: sum(recorder.stats.samples.values()) >= expect, timeout=5,
                 why=lambda: f"{dict(recorder.stats.samples)}")
        recorder.close()
    return recorder


def test_every_sample_is_recorded_in_order_with_its_times_and_a_json_copy(
        make_bus: Callable[..., Bus], tmp_path: Path) -> None:
    publisher, recorder_bus = make_bus(), make_bus()
    path = tmp_path / "run.mcap"
    t0 = time.time()

    def publish() -> None:
        for i in range(50):
            publisher.publish(keys.TRACKER_ROBOT, _robot(i, t0 + i * 0.01))
        publisher.publish(keys.GANTRY_FRAME, _frame(t0))
        publisher.session.put("stb/tracker/robot", b"\xc1 not msgpack")

    recorder = _record(recorder_bus, path, publish, expect=52, scene=LabScene(),
                       heard=(publisher, ROBOT))
    assert recorder.stats.invalid == {"stb/tracker/robot: not_msgpack": 1}
    assert recorded_keys(path) == {"stb/tracker/robot": 51, "stb/gantry/camera/frame": 1}
    robot = list(read_samples(path, ["stb/tracker/robot"]))
    assert [s.sequence for s in robot] == list(range(1, 52))
    decoded = [codec.decode(m.RobotPosition, s.payload) for s in robot[:50]]
    assert [d.x_mm for d in decoded] == [float(i) for i in range(50)]
    assert robot[-1].payload == b"\xc1 not msgpack", "invalid payloads are kept as bytes"
    assert all(s.measured_s == pytest.approx(d.measured_s, abs=1e-6)
               for s, d in zip(robot, decoded, strict=False))
    assert all(a.received_s <= b.received_s for a, b in zip(robot, robot[1:], strict=False))
    assert all(s.encoding.startswith(codec.CONTENT_TYPE) for s in robot)

    with open(path, "rb") as f:
        copies = {c.topic: (c, s) for s, c, _ in make_reader(f).iter_messages()
                  if s is not None}
    assert "json/stb/gantry/camera/frame" not in copies, "images go to the typed channels"
    channel, schema = copies["/gantry/image"]
    assert channel.message_encoding == "protobuf" and schema.name == "foxglove.CompressedImage"
    image = decoded_typed(path, "/gantry/image")[0]
    assert image.format == "jpeg" and image.frame_id == "tracking"
    assert image.data.startswith(b"\xff\xd8"), "the frame as a JPEG"
    channel, schema = copies["json/stb/tracker/robot"]
    assert schema.name == "stb.RobotPosition" and schema.encoding == "jsonschema"
    assert json.loads(schema.data)["properties"]["x_mm"]["type"] == "number"
    with open(path, "rb") as f:
        first = next(json.loads(msg.data) for _, c, msg in make_reader(f).iter_messages(
            topics=["json/stb/tracker/robot"]))
    assert first["x_mm"] == 0.0 and first["label"] == "robot"


def test_replay_puts_the_same_messages_back_in_order_and_on_time(
        make_bus: Callable[..., Bus], tmp_path: Path) -> None:
    """A recording of 20 robot samples heard 50 ms apart (written as the recorder writes
    them), replayed at speed 2."""
    from common.mcap_file import RecordWriter

    listener = make_bus()
    path = tmp_path / "run.mcap"
    with open(path, "wb") as out:
        writer = RecordWriter(out)
        for i in range(20):
            t = 1000.0 + i * 0.05
            writer.write(ROBOT, codec.encode(_robot(i, t)), encoding=codec.CONTENT_TYPE,
                         model="RobotPosition", received_s=t, measured_s=t)
        writer.finish()
    got: list[tuple[float, m.RobotPosition]] = []
    listener.subscribe(keys.TRACKER_ROBOT, lambda r: got.append((time.time(), r)),
                       latest=False)
    until_heard(listener, ROBOT)
    started = time.time()
    sent = replay(listener.session, path, speed=2.0)
    wait_for(lambda: len(got) == 20, timeout=5)
    assert sent == {"stb/tracker/robot": 20}
    assert [r.x_mm for _, r in got] == [float(i) for i in range(20)]
    took = got[-1][0] - got[0][0]
    assert 0.35 < took < 0.8, f"19 gaps of 50 ms at speed 2 took {took:.2f} s"
    measured = [r.measured_s for _, r in got]
    assert measured[0] == pytest.approx(started, abs=0.2), "retimed to the replay's clock"
    assert np.diff(measured) == pytest.approx([0.025] * 19, abs=2e-3), "offsets / speed"


def test_a_replay_ends_only_when_its_last_samples_have_left(router_endpoint: str,
                                                           make_bus: Callable[..., Bus],
                                                           tmp_path: Path) -> None:
    """A recording that ends with a burst of 32 pictures of 60 kB, replayed five times by
    ``stb replay``: every picture arrives every time. A process that closed its session
    right after its last put lost the burst's tail in about a third of such runs
    (``common.bus.SEND_LINGER_S``)."""
    from common.mcap_file import RecordWriter

    path = tmp_path / "burst.mcap"
    noise = np.random.default_rng(1).integers(0, 255, 60_000, dtype=np.uint8).tobytes()
    with open(path, "wb") as out:
        writer = RecordWriter(out)
        for i in range(32):
            frame = m.CameraFrame(measured_s=1000.0, camera="ptz1", seq=i + 1, width_px=704,
                                  height_px=576, encoding="jpeg", data=noise)
            writer.write("stb/video/ptz1", codec.encode(frame), encoding=codec.CONTENT_TYPE,
                         model="CameraFrame", received_s=1000.0, measured_s=1000.0)
        writer.finish()
    listener = make_bus()
    seqs: list[int] = []
    listener.subscribe(keys.VIDEO, lambda f: seqs.append(f.seq), latest=False, camera="ptz1")
    until_heard(listener, "stb/video/ptz1")
    for _ in range(5):
        seqs.clear()
        replayed = stb_process("replay", str(path), "--connect", router_endpoint)
        assert replayed.wait(timeout=60) == 0, replayed.stderr.read()
        wait_for(lambda: len(seqs) == 32, timeout=10,
                 why=lambda: f"pictures {sorted(seqs)} of 1-32")
        assert seqs == list(range(1, 33))


def test_replay_as_recorded_sends_the_exact_bytes(make_bus: Callable[..., Bus],
                                                  tmp_path: Path) -> None:
    publisher, recorder_bus, listener = make_bus(), make_bus(), make_bus()
    path = tmp_path / "run.mcap"
    t0 = time.time()
    _record(recorder_bus, path, lambda: [publisher.publish(keys.TRACKER_ROBOT, _robot(i, t0))
                                         for i in range(5)], expect=5, heard=(publisher, ROBOT))
    raw: list[bytes] = []
    sub = listener.session.declare_subscriber("stb/**", lambda s: raw.append(
        s.payload.to_bytes()))
    until_heard(listener, ROBOT)
    replay(listener.session, path, speed=10.0, as_recorded=True)
    wait_for(lambda: len(raw) == 5, timeout=5)
    sub.undeclare()
    assert raw == [s.payload for s in read_samples(path)]


def test_retimed_moves_clock_fields_only() -> None:
    msg = _robot(3, 1000.5)
    payload = codec.encode(msg, sent_s=1000.6)
    out = codec.decode(m.RobotPosition, retimed(payload, origin_s=1000.0, start_s=5000.0,
                                                speed=2.0, sent_s=5000.9))
    assert out.measured_s == pytest.approx(5000.25)
    assert out.sent_s == 5000.9
    assert out.model_dump(exclude={"measured_s", "sent_s"}) == msg.model_dump(
        exclude={"measured_s", "sent_s"})
    assert retimed(b"\xc1", origin_s=0, start_s=1, speed=1, sent_s=1) == b"\xc1"


def test_pace_stops_when_asked() -> None:
    import threading

    from common.mcap_file import Sample

    samples = [Sample("k", b"", "", 100.0 + i, 100.0 + i, i + 1) for i in range(3)]
    stop = threading.Event()
    stop.set()
    assert [s for s, *_ in pace(samples, 1.0, stop)] == []


def test_a_file_that_is_not_a_recording_is_a_clear_error(tmp_path: Path) -> None:
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"not an mcap file at all")
    with pytest.raises(RecordingError, match="no MCAP header"):
        recorded_keys(bad)
    with pytest.raises(RecordingError):
        list(read_samples(bad))


def test_recorder_skips_keys_it_excludes(make_bus: Callable[..., Bus], tmp_path: Path) -> None:
    publisher, recorder_bus = make_bus(), make_bus()
    out = io.BytesIO()
    recorder = Recorder(recorder_bus.session, "stb", ["stb/**", "stb/tracker/**"], out,
                        exclude=["stb/gantry/**"])
    until_heard(publisher, ROBOT)
    publisher.publish(keys.GANTRY_FRAME, _frame(time.time()))
    publisher.publish(keys.TRACKER_ROBOT, _robot(1, time.time()))
    wait_for(lambda: recorder.stats.samples, timeout=5)
    # one more sample, on a key only "stb/**" covers: it comes in behind the others, so once
    # it is recorded the excluded frame and any second copy of the robot's would have been too
    publisher.publish(keys.PTZ_STATE, example(m.PtzState), camera="ptz1")
    wait_for(lambda: "stb/ptz/ptz1/state" in recorder.stats.samples, timeout=5)
    recorder.close()
    assert dict(recorder.stats.samples) == {"stb/tracker/robot": 1, "stb/ptz/ptz1/state": 1}, \
        "excluded keys left out, overlapping expressions recorded once"
    assert zenoh.KeyExpr("stb/**").includes(zenoh.KeyExpr("stb/tracker/robot"))


def test_a_recording_that_was_never_finished_is_read_up_to_where_it_breaks_off(
        tmp_path: Path) -> None:
    from common.mcap_file import RecordWriter

    out = io.BytesIO()
    writer = RecordWriter(out)
    payloads = [codec.encode(_robot(i, 1000.0 + i)) for i in range(3000)]
    for i, payload in enumerate(payloads):
        writer.write("stb/tracker/robot", payload, encoding=codec.CONTENT_TYPE,
                     model="RobotPosition", received_s=1000.0 + i, measured_s=1000.0 + i)
    path = tmp_path / "killed.mcap"
    path.write_bytes(out.getvalue())  # no finish(): as if the recorder was killed -9
    salvaged = list(read_samples(path))
    assert 1000 < len(salvaged) < 3000, "the chunks written before the cut"
    assert [s.payload for s in salvaged] == payloads[:len(salvaged)]
    assert recorded_keys(path) == {"stb/tracker/robot": len(salvaged)}


def test_a_calibration_snapshot_is_stored_once_as_h264(make_bus: Callable[..., Bus],
                                                      tmp_path: Path) -> None:
    """A PTZ camera's snapshots in calibration mode are a camera stream: in the file as H.264
    on /CAMERA/snapshot only, not also as bus samples (those with --raw-frames)."""
    import cv2

    publisher, recorder_bus = make_bus(), make_bus()
    path = tmp_path / "run.mcap"
    t0, rng = time.time(), np.random.default_rng(2)
    background = (rng.random((576, 704, 3)) * 120).astype(np.uint8)  # a noisy still scene
    snapshots = []
    for i in range(12):
        picture = background.copy()
        cv2.circle(picture, (100 + 40 * i, 300), 6, (255, 255, 255), -1)  # the wand
        jpeg = cv2.imencode(".jpg", picture, [cv2.IMWRITE_JPEG_QUALITY, 85])[1].tobytes()
        snapshots.append(m.CameraFrame(measured_s=t0 + i / 10, camera="ptz1", seq=i + 1,
                                       width_px=704, height_px=576, encoding="jpeg",
                                       data=jpeg))

    def publish() -> None:
        publish_paced(publisher, keys.PTZ_SNAPSHOT, snapshots, 0.02, camera="ptz1")

    recorder = _record(recorder_bus, path, publish, expect=10, scene=LabScene(video=True),
                       raw_frames=False, heard=(publisher, "stb/ptz/ptz1/snapshot"))
    count = recorder.stats.samples["stb/ptz/ptz1/snapshot"]
    assert "stb/ptz/ptz1/snapshot" not in recorded_keys(path), "stored once: no bus samples"
    video = decoded_typed(path, "/ptz1/snapshot")
    assert len(video) == count and {v.format for v in video} == {"h264"}
    decoder = av.CodecContext.create("h264", "r")
    decoded = [image for v in video for image in decoder.decode(av.Packet(v.data))]
    assert [(d.width, d.height) for d in decoded] == [(704, 576)] * count
    jpeg_bytes = sum(len(s.data) for s in snapshots[:count])
    assert path.stat().st_size < jpeg_bytes, (path.stat().st_size, jpeg_bytes)


def test_camera_frames_are_recorded_as_h264_video_that_decodes_in_order_on_their_times(
        make_bus: Callable[..., Bus], tmp_path: Path) -> None:
    """Without --raw-frames the tracking camera's frames are in the file only as Foxglove's
    CompressedVideo (H.264, a keyframe first, one access unit per frame at its capture time);
    PyAV decodes them back to frames of the camera's size, and the file is a fraction of the
    raw frames' size."""
    publisher, recorder_bus = make_bus(), make_bus()
    path = tmp_path / "run.mcap"
    t0, rng = time.time(), np.random.default_rng(1)
    frames = [m.CameraFrame(measured_s=t0 + i / 30, camera="tracking", seq=i + 1, width_px=640,
                            height_px=480, encoding="mono8",
                            data=draw([Blob(200 + 4 * i, 240, 6, 6)], 640, 480, rng).tobytes())
              for i in range(30)]

    def publish() -> None:
        publish_paced(publisher, keys.GANTRY_FRAME, frames, 1 / 30)  # 9 MB in all

    recorder = _record(recorder_bus, path, publish, expect=25,  # most of them, on a busy machine
                       scene=LabScene(video=True), raw_frames=False,
                       heard=(publisher, "stb/gantry/camera/frame"))
    count = recorder.stats.samples["stb/gantry/camera/frame"]
    assert "stb/gantry/camera/frame" not in recorded_keys(path), "no raw frames"
    with open(path, "rb") as f:
        schemas = {c.topic: s.name for s, c, _ in make_reader(f).iter_messages()
                   if s is not None}
    assert schemas["/gantry/image"] == "foxglove.CompressedVideo"
    video = decoded_typed(path, "/gantry/image")
    assert [v.format for v in video] == ["h264"] * count and video[0].frame_id == "tracking"
    stamps = [v.timestamp.seconds + v.timestamp.nanos * 1e-9 for v in video]
    sent = [f.measured_s for f in frames]
    assert all(any(abs(t - s) < 1e-6 for s in sent) for t in stamps) and stamps == sorted(stamps)
    assert video[0].data.startswith(b"\x00\x00\x00\x01"), "Annex B, SPS first"
    decoder = av.CodecContext.create("h264", "r")
    decoded = [image for v in video for image in decoder.decode(av.Packet(v.data))]
    assert [(d.width, d.height) for d in decoded] == [(640, 480)] * count
    brightest = [np.unravel_index(np.argmax(d.to_ndarray(format="gray")), (480, 640))[1]
                 for d in decoded]
    assert brightest == sorted(brightest) and brightest[-1] - brightest[0] > 80, \
        "the spot moves right, frame after frame: the video is the frames in order"
    raw_mb = sum(len(f.data) for f in frames) / 1e6
    assert path.stat().st_size < raw_mb * 1e6 / 20, (path.stat().st_size, raw_mb)
