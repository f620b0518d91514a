"""A recording of a short sim run: every key, in order, decodable; replayed, the same
messages come back; the report renders from it."""

from __future__ import annotations

import json
import signal
import time
from collections import defaultdict
from pathlib import Path

import av
import cv2
import numpy as np
import pytest
from mcap.reader import make_reader

from common import codec, keys
from common import messages as m
from common.bus import Bus
from common.mcap_file import read_samples, recorded_keys
from tests.calib.test_demo_calibration import MOUNTS
from tests.conftest import client_settings, open_when_up, stb_process, until_heard, wait_for
from tests.operator.conftest import LiveLab
from tests.ports import free_port
from tests.recording.typed import decoded_typed
from tests.services.test_processes import _stop

EXPECTED = ["stb/tracker/markers", "stb/tracker/robot", "stb/gantry/state",
            "stb/gantry/setpoint", "stb/gantry/estimate", "stb/gantry/detections",
            "stb/gantry/offload", "stb/ptz/ptz1/state",
            "stb/ptz/ptz2/state", "stb/ptz/ptz1/preview", "stb/ptz/ptz2/preview",
            "stb/sim/truth/crane", "stb/sim/truth/robot/locomotive", "stb/health/gantry/main",
            "stb/health/tracker/main", "stb/health/sim/main", "stb/health/web/main",
            # --raw-frames: the camera streams as bus samples too (replayed below)
            "stb/gantry/camera/frame", "stb/video/ptz1", "stb/video/ptz2"]
VIDEO_FPS = 4.0
RECORD_S = 8.0

pytestmark = pytest.mark.system  # a whole lab recorded on real time: make test-system


@pytest.fixture(scope="module")
def birdseye_carried(live_lab: LiveLab) -> list[float]:
    """When the bird's-eye pictures reached a subscriber beside the recorder while
    ``recording`` was made (wall clock; filled as they come)."""
    return []


@pytest.fixture(scope="module")
def recording(live_lab: LiveLab, birdseye_carried: list[float],
              tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("rec") / "run.mcap"
    settings = client_settings(live_lab.endpoint)
    session = open_when_up(settings.zenoh)
    bus = Bus(session, settings)
    try:
        bus.subscribe(keys.VIDEO, lambda _: birdseye_carried.append(time.time()), latest=False,
                      camera="observation")
        proc = stb_process("record", str(out), "--lab", str(live_lab.lab), "--duration",
                           str(RECORD_S), "--set", "progress_s=2",
                           "--set", f"height_map={live_lab.crater_file}",
                           "--video", "ptz1", "--video", "ptz2", "--video-fps",
                           str(VIDEO_FPS), "--raw-frames")
        assert proc.wait(timeout=RECORD_S + 30) == 0, proc.stderr.read()
    finally:
        bus.close()
        session.close()
    log = proc.stderr.read()
    assert "wrote" in log and "samples" in log
    print(log)
    return out


def test_the_recording_has_every_key_in_order_and_decodable(recording: Path) -> None:
    counts = recorded_keys(recording)
    missing = [k for k in EXPECTED if not counts.get(k)]
    assert not missing, f"not recorded: {missing} (recorded: {sorted(counts)})"
    assert counts["stb/tracker/markers"] > 50 * RECORD_S, "the mocap runs at 100 Hz"
    last: dict[str, tuple[float, int]] = {}
    received = []
    for sample in read_samples(recording):
        received.append(sample.received_s)
        topic = keys.topic_for("stb", sample.key)
        assert topic is not None, sample.key
        msg = codec.decode(topic.model, sample.payload, max_bytes=topic.max_payload_bytes)
        assert sample.measured_s == pytest.approx(msg.measured_s, abs=1e-6)
        previous = last.get(sample.key)
        if previous is not None:
            assert sample.sequence == previous[1] + 1, f"{sample.key}: a sample is missing"
        last[sample.key] = (sample.received_s, sample.sequence)
    assert received == sorted(received), "in the order they were received"
    assert received[-1] - received[0] > RECORD_S - 1.5


def test_the_recording_opens_in_foxglove_with_typed_channels(
        recording: Path, birdseye_carried: list[float]) -> None:
    """What Foxglove's 3D, image and plot panels read: typed (protobuf) channels with their
    schemas, whose content is the run's — read with the mcap library, decoded by the file's own
    schemas."""
    with open(recording, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    typed = {c.topic: summary.schemas[c.schema_id] for c in summary.channels.values()
             if c.message_encoding == "protobuf"}
    expected = {
        "/scene": "foxglove.SceneUpdate", "/crater": "foxglove.SceneUpdate",
        "/tf": "foxglove.FrameTransforms", "/gantry/image": "foxglove.CompressedVideo",
        "/ptz1/image": "foxglove.CompressedImage", "/ptz2/image": "foxglove.CompressedImage",
        "/ptz1/annotations": "foxglove.ImageAnnotations",
        "/ptz2/annotations": "foxglove.ImageAnnotations",
        "/ptz1/video": "foxglove.CompressedVideo", "/ptz2/video": "foxglove.CompressedVideo",
        "/observation/video": "foxglove.CompressedVideo"}  # the bird's-eye view
    # the bird's-eye view is not pulled at --video-fps: it comes as the sim's observation
    # camera renders it, on the processor time the lab leaves (SCHED_IDLE), so its count
    # follows the machine's load (5 in 8 s in a CI run beside another lab; none at all in
    # another, beside a lab ahead of this one at nice −10). Its channel is asked for when the
    # bus carried a picture well inside the recording (a second from either end); that every
    # one the bus carried is recorded is test_demo_recording's
    received = [s.received_s for s in read_samples(recording, ["stb/tracker/robot"])]
    inside = [t for t in birdseye_carried if received[0] + 1 <= t <= received[-1] - 1]
    print(f"bird's-eye pictures carried well inside the recording: {len(inside)}")
    names = {t: s.name for t, s in typed.items()}
    if not inside:
        expected.pop("/observation/video")
        names.pop("/observation/video", None)
    assert names == expected
    videos = ("/gantry/image", "/ptz1/video", "/ptz2/video", "/observation/video")
    for topic in [t for t in videos if t in expected]:
        decoder = av.CodecContext.create("h264", "r")
        units = decoded_typed(recording, topic)
        frames = [f for u in units for f in decoder.decode(av.Packet(u.data))]
        pulled = topic != "/observation/video"
        assert len(frames) == len(units) > (2 * VIDEO_FPS if pulled else 0), topic
        stamps = [u.timestamp.seconds + u.timestamp.nanos * 1e-9 for u in units]
        assert stamps == sorted(stamps), f"{topic}: in time order"
    schemaless = [c.topic for c in summary.channels.values()
                  if c.topic.startswith("json/") and c.schema_id == 0]
    assert not schemaless, f"JSON copies without a schema: {schemaless}"
    robot = {round(s.measured_s, 3): codec.decode(m.RobotPosition, s.payload)
             for s in read_samples(recording, ["stb/tracker/robot"])}
    scenes = decoded_typed(recording, "/scene")
    assert len(scenes) >= 5 * RECORD_S, "about 10 a second"
    for scene in scenes[10:: 10]:  # from a second in: the crane has reported by then
        [entity] = [e for e in scene.entities if e.id == "robot"]
        t = round(entity.timestamp.seconds + entity.timestamp.nanos / 1e9, 3)
        position = entity.spheres[0].pose.position
        # the scene is stamped by the message that sent it (a robot sample, or the crane's
        # state when that came first: CI's busy run), and shows the latest robot sample
        recent = [r for at, r in robot.items() if t - 0.5 <= at <= t + 1e-3]
        assert any((position.x, position.y) == pytest.approx((r.x_mm / 1000, r.y_mm / 1000))
                   for r in recent), "the robot where the tracker put it"
        assert {"crane", "camera/ptz1", "camera/ptz2"} <= {e.id for e in scene.entities}
    heads = {f.child_frame_id: f for tf in decoded_typed(recording, "/tf")
             for f in tf.transforms}
    for camera, mount in MOUNTS.items():
        moved = heads[camera].translation
        assert (moved.x, moved.y, moved.z) == pytest.approx(
            (mount.x_mm / 1000, mount.y_mm / 1000, mount.z_mm / 1000), abs=1e-3)
    [crater] = decoded_typed(recording, "/crater")[:1]
    assert len(crater.entities[0].triangles[0].points) > 1000
    previews = {round(s.measured_s, 6): codec.decode(m.PtzPreview, s.payload)
                for s in read_samples(recording, ["stb/ptz/ptz1/preview"])}
    images = decoded_typed(recording, "/ptz1/image")
    assert len(images) == len(previews) and all(i.data[:2] == b"\xff\xd8" for i in images)
    for notes in decoded_typed(recording, "/ptz1/annotations"):
        t = round(notes.circles[0].timestamp.seconds + notes.circles[0].timestamp.nanos / 1e9,
                  6) if notes.circles else None
        if t is not None and t in previews:
            assert len(notes.circles) == len(previews[t].markers)


def test_each_cameras_video_is_in_the_recording_on_the_buss_clock(recording: Path) -> None:
    """``--video``: each camera's MJPEG, frame by frame, at about the rate asked for, every
    frame a whole 704×576 JPEG, stamped on the clock of the recorded bus samples (so that it
    lines up with the mocap and the gantry), and in Foxglove's typed channel too."""
    robot = [s.received_s for s in read_samples(recording, ["stb/tracker/robot"])]
    for camera in ("ptz1", "ptz2"):
        frames = [codec.decode(m.CameraFrame, s.payload)
                  for s in read_samples(recording, [f"stb/video/{camera}"])]
        assert 0.6 * VIDEO_FPS * RECORD_S <= len(frames) <= 1.2 * VIDEO_FPS * RECORD_S + 2, \
            len(frames)
        assert [f.seq for f in frames] == list(range(1, len(frames) + 1))
        assert {(f.width_px, f.height_px, f.encoding) for f in frames} == {(704, 576, "jpeg")}
        picture = cv2.imdecode(np.frombuffer(frames[-1].data, np.uint8), cv2.IMREAD_COLOR)
        assert picture is not None, "not a JPEG"
        assert picture.shape == (576, 704, 3) and picture.std() > 5, "a picture, not a field"
        times = [f.measured_s for f in frames]
        assert robot[0] - 1.0 <= times[0] and times[-1] <= robot[-1] + 1.0, "the same clock"
        gaps = np.diff(times)
        assert np.median(gaps) == pytest.approx(1 / VIDEO_FPS, rel=0.25)
        assert len(decoded_typed(recording, f"/{camera}/video")) == len(frames)


def test_replaying_the_recording_gives_the_same_messages(recording: Path) -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = stb_process("router", "--listen", endpoint, "--set", "bus.zenoh.connect=[]")
    session = None
    try:
        settings = client_settings(endpoint)
        session = open_when_up(settings.zenoh)
        bus = Bus(session, settings)
        got: dict[str, list[m.Message]] = defaultdict(list)

        def heard(item: tuple[str, m.Message | dict]) -> None:
            if isinstance(item[1], m.Message):  # a key the project does not know: not counted
                got[item[0]].append(item[1])

        chosen = ["stb/tracker/robot", "stb/gantry/state", "stb/ptz/ptz1/state",
                  "stb/video/ptz1"]
        for key in chosen:
            bus.subscribe_any(key, heard)
        probe = open_when_up(settings.zenoh)
        try:  # the subscriptions have reached the router before the replay starts
            prober = Bus(probe, settings)
            for key in chosen:
                until_heard(prober, key)
        finally:
            probe.close()
        replay = stb_process("replay", str(recording), "--speed", "4", "--connect", endpoint,
                             *[a for key in chosen for a in ("--keys", key)])
        assert replay.wait(timeout=RECORD_S + 20) == 0, replay.stderr.read()
        topics = {k: keys.topic_for("stb", k) for k in chosen}
        assert None not in topics.values()
        expected = {k: [codec.decode(topics[k].model, s.payload)  # type: ignore[union-attr]
                        for s in read_samples(recording, [k])] for k in chosen}
        try:
            wait_for(lambda: all(len(got[k]) == len(expected[k]) for k in chosen), timeout=5)
        except BaseException:
            print({k: (len(got[k]), len(expected[k])) for k in chosen})
            raise
        for key in chosen:
            clock = {"measured_s", "sent_s"}
            assert [g.model_dump(exclude=clock) for g in got[key]] == [
                e.model_dump(exclude=clock) for e in expected[key]], key
            shifts = [g.measured_s - e.measured_s for g, e in zip(got[key], expected[key],
                                                                   strict=True)]
            assert max(shifts) - min(shifts) < RECORD_S, "one shift for the whole run (/4)"
        bus.close()
    finally:
        if session is not None:
            session.close()
        _stop(router, signal.SIGINT)


def test_the_report_renders_from_the_recording(recording: Path, live_lab: LiveLab,
                                               tmp_path: Path) -> None:
    out = tmp_path / "report"
    proc = stb_process("report", str(recording), "--out", str(out), "--height-map",
                       str(live_lab.crater_file))
    assert proc.wait(timeout=120) == 0, proc.stderr.read()
    for name in ("errors.png", "tracks.png", "velocity.png", "calibration.png", "aim.png"):
        data = (out / name).read_bytes()
        assert data.startswith(b"\x89PNG") and len(data) > 10_000, name
    page = (out / "index.html").read_text()
    assert all(f'src="{n}"' in page for n in ("errors.png", "tracks.png", "velocity.png"))
    figures = json.loads((out / "summary.json").read_text())
    assert figures["gantry_algorithm"] == "default"
    assert 0 < figures["crane_error_mean_mm"] < 500, figures
    assert figures["ptz1_pose_passpoints"] == 100
    assert figures["ptz1_aim_error_median_deg"] < 5
