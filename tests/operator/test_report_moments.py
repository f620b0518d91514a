"""The report's pictures of a run: stills from the recorded H.264 videos at the largest crane
error and where alarms began, and ``stb report --video``'s bird's-eye MP4 with the crane's
error written over it. The recording is made as ``stb record`` makes it (its scene encodes
the observation camera's JPEGs as H.264), each frame carrying its number as a bright bar, so
a still shows which frame it is."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import av
import cv2
import numpy as np
import pytest

from common import codec, keys
from common import messages as m
from common.mcap_file import RecordWriter
from services.recording.typed import LabScene
from services.report.birdseye import error_at
from services.report.data import moments, read_recording
from services.report.video import is_keyframe, still
from tests.conftest import ROOT

T0, FPS, SECONDS = 1.7e9, 5, 40
PEAK_S, STALE_S = 23.0, 31.0  # the largest error, and the crane going stale


def _frame_image(n: int) -> np.ndarray:
    """Frame ``n``: a bright bar at column 8 n (which frame a still is)."""
    image = np.full((240, 320, 3), (90, 110, 120), np.uint8)
    cv2.rectangle(image, (8 * n % 320, 60), (8 * n % 320 + 6, 180), (255, 255, 255), -1)
    return image


def _put(writer: RecordWriter, topic: keys.Topic, msg: m.Message, **params: str) -> None:
    writer.write(topic.key("stb", **params), codec.encode(msg, sent_s=msg.measured_s),
                 encoding=codec.CONTENT_TYPE, model=topic.model.__name__,
                 received_s=msg.measured_s, measured_s=msg.measured_s)


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("moments") / "run.mcap"
    scene = LabScene(video=True)
    with open(path, "wb") as f:
        writer = RecordWriter(f)
        for i in range(SECONDS * 25):  # mocap and crane at 25 Hz
            t = T0 + i / 25
            error = 150.0 if abs(t - T0 - PEAK_S) < 0.02 else 30.0
            _put(writer, keys.TRACKER_ROBOT, m.RobotPosition(
                measured_s=t, label="robot", x_mm=0.0, y_mm=0.0, z_mm=0.0, vx_mm_s=0.0,
                vy_mm_s=0.0, vz_mm_s=0.0))
            _put(writer, keys.GANTRY_STATE, m.CraneState(
                measured_s=t, status="stale" if t - T0 >= STALE_S else "tracking",
                x_mm=error, y_mm=0.0, target_x_mm=0.0, target_y_mm=0.0, enabled=True,
                moving=True, fault_bits=0, mode="armed"))
            if i % (25 // FPS) == 0:
                n = i // (25 // FPS)
                ok, jpeg = cv2.imencode(".jpg", _frame_image(n))
                frame = m.CameraFrame(measured_s=t, camera="observation", seq=n + 1,
                                      width_px=320, height_px=240, encoding="jpeg",
                                      data=jpeg.tobytes())
                for typed in scene.on(frame, keys.VIDEO):
                    writer.write_typed(typed.topic, schema=(typed.schema_name,
                                       typed.schema_encoding, typed.schema_data),
                                       message_encoding=typed.message_encoding,
                                       data=typed.data, time_s=typed.time_s)
        writer.finish()
    return path


def _bar_column(image: np.ndarray) -> int:
    bright = np.nonzero(np.all(image[120] > 220, axis=1))[0]
    return int(bright.min())


def test_the_moments_are_the_largest_error_and_where_alarms_began(recording: Path) -> None:
    rec = read_recording(recording)
    found = moments(rec)
    assert [round(t - T0, 2) for t, _ in found] == [PEAK_S, STALE_S]
    assert "largest crane error, 150 mm" in found[0][1] and found[1][1] == "crane stale"


def test_a_still_is_the_frame_taken_last_before_its_moment(recording: Path) -> None:
    found = still([recording], "/observation/video", T0 + PEAK_S + 0.1)
    assert found is not None
    when, image = found
    n = round((when - T0) * FPS)
    assert when == pytest.approx(T0 + PEAK_S, abs=1e-3) and image.shape == (240, 320, 3)
    assert abs(_bar_column(image) - 8 * n % 320) <= 2, "the picture of that very frame"
    assert still([recording], "/observation/video", T0 - 100) is None
    assert not is_keyframe(b"\x00\x00\x01\x41abc") and is_keyframe(b"\x00\x00\x01\x65abc")


def test_stb_report_shows_stills_and_exports_the_bird_s_eye_mp4(recording: Path,
                                                                tmp_path: Path) -> None:
    done = subprocess.run([sys.executable, "-m", "services.cli", "report", str(recording),
                           "--out", str(tmp_path), "--video", "--video-seconds", "10"],
                          cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    page = (tmp_path / "index.html").read_text()
    assert "Moments" in page and "largest crane error, 150 mm" in page and "crane stale" in page
    assert (tmp_path / "still-1-observation-video.jpg").exists()
    assert (tmp_path / "still-2-observation-video.jpg").exists()
    with av.open(str(tmp_path / "birdseye.mp4")) as mp4:
        stream = mp4.streams.video[0]
        frames = [(float(f.pts * f.time_base), f.to_ndarray(format="bgr24"))  # type: ignore[operator]
                  for f in mp4.decode(stream)]
    assert len(frames) == pytest.approx(10 * FPS, abs=2), "ten seconds at the camera's rate"
    assert (frames[0][1].shape[1], frames[0][1].shape[0]) == (320, 240)
    times = [t for t, _ in frames]
    assert times == sorted(times) and times[-1] - times[0] == pytest.approx(10, abs=0.5)
    assert all(image[:26].mean() < image[30:].mean() for _, image in frames), "a caption bar"


def test_a_recording_whose_recorder_was_killed_is_reported_up_to_where_it_breaks_off(
        recording: Path, tmp_path: Path) -> None:
    """The page kills a recorder that does not finish within its wait after a stop (a loaded
    machine: seen with three labs on two cores): its file breaks off inside a chunk, with no
    summary, and the report's stills and video are read from what is there."""
    whole = recording.read_bytes()
    cut = tmp_path / "killed.mcap"
    cut.write_bytes(whole[:int(len(whole) * 0.7)])  # past the largest error, before the end
    found = still([cut], "/observation/video", T0 + PEAK_S + 0.1)
    assert found is not None and found[0] == pytest.approx(T0 + PEAK_S, abs=1e-3)
    done = subprocess.run([sys.executable, "-m", "services.cli", "report", str(cut),
                           "--out", str(tmp_path / "report")],
                          cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert "was not finished" in done.stderr
    page = (tmp_path / "report" / "index.html").read_text()
    assert "largest crane error, 150 mm" in page
    assert (tmp_path / "report" / "still-1-observation-video.jpg").exists()


def test_the_error_shown_is_the_one_measured_nearest_the_frame() -> None:
    t, error = np.array([1.0, 2.0, 3.0]), np.array([10.0, 20.0, 30.0])
    assert error_at(t, error, 2.2) == 20.0 and error_at(t, error, 2.6) == 30.0
    assert error_at(t, error, 9.0) is None and error_at(np.empty(0), np.empty(0), 1.0) is None


def test_a_video_channel_that_is_not_foxglove_s_is_left_out(tmp_path: Path) -> None:
    path = tmp_path / "odd.mcap"
    with open(path, "wb") as f:
        writer = RecordWriter(f)
        for i in range(5):
            writer.write_typed("/odd/video", schema=("foxglove.CompressedVideo", "protobuf",
                                                     b"not descriptors"),
                               message_encoding="protobuf", data=b"\x00\x01", time_s=T0 + i)
        writer.finish()
    assert still([path], "/odd/video", T0 + 4) is None
