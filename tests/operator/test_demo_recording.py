"""A minute of the demo lab (gantry armed, locomotive) recorded as a lab records it: every
camera as H.264 on Foxglove's CompressedVideo channels — both PTZ cameras (--video), the
observation camera's bird's-eye view (stb observation) and the tracking camera — each decoding
to pictures of its camera's size in time order, on the clock the mocap and the gantry are on,
at no more than 30 MB a minute.

The recorder pulls the PTZ cameras' video and the tracking camera's frames at the lab's rates;
the bird's-eye view it takes from the bus as the observation service sent it. The sim's
observation camera renders only on processor time the lab leaves (as a real one renders on its
own processor), so on a busy machine it sends fewer than its 5 a second: the recording must
hold every one of those the bus carried, however many that was."""

from __future__ import annotations

from pathlib import Path

import av
import numpy as np
import pytest
from mcap.reader import make_reader

from common import keys
from common.bus import Bus, open_session
from common.mcap_file import read_samples
from tests.conftest import client_settings, stb_process
from tests.operator.conftest import LiveLab
from tests.recording.typed import decoded_typed

RECORD_S = 60.0
MB_PER_MINUTE = 30.0
CHANNELS = {"/ptz1/video": (704, 576, 5.0), "/ptz2/video": (704, 576, 5.0),
            "/observation/video": (640, 480, 5.0), "/gantry/image": (640, 480, 25.0)}
"""Each video channel: its camera's size and frame rate (what the lab asks of it)."""
BIRDSEYE = "/observation/video"

pytestmark = pytest.mark.system


@pytest.fixture(scope="module")
def sent_birdseye(live_lab: LiveLab) -> list[float]:
    """The capture times of the bird's-eye pictures the bus carried while ``minute`` was
    recorded (filled as they come)."""
    return []


@pytest.fixture(scope="module")
def minute(live_lab: LiveLab, sent_birdseye: list[float],
           tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("minute") / "demo.mcap"
    settings = client_settings(live_lab.endpoint)
    session = open_session(settings.zenoh)
    try:
        bus = Bus(session, settings)
        bus.subscribe(keys.VIDEO, lambda f: sent_birdseye.append(f.measured_s), latest=False,
                      camera="observation")
        proc = stb_process("record", str(out), "--lab", str(live_lab.lab), "--duration",
                           str(RECORD_S), "--set", f"height_map={live_lab.crater_file}",
                           "--video", "ptz1", "--video", "ptz2")
        assert proc.wait(timeout=RECORD_S + 60) == 0, proc.stderr.read()
        bus.close()
    finally:
        session.close()
    return out


def _stamps(video: list) -> np.ndarray:
    return np.array([v.timestamp.seconds + v.timestamp.nanos * 1e-9 for v in video])


def test_every_camera_is_h264_that_decodes_in_time_order(minute: Path,
                                                         sent_birdseye: list[float]) -> None:
    with open(minute, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None
        schemas = {c.topic: summary.schemas[c.schema_id].name
                   for c in summary.channels.values() if c.schema_id}
    for topic, (width, height, fps) in CHANNELS.items():
        assert schemas.get(topic) == "foxglove.CompressedVideo", topic
        video = decoded_typed(minute, topic)
        stamps = _stamps(video)
        assert np.all(np.diff(stamps) > 0), f"{topic}: in time order"
        if topic == BIRDSEYE:
            _holds_every_picture_sent(stamps, np.array(sent_birdseye))
        else:
            assert len(video) >= 0.8 * fps * RECORD_S, \
                f"{topic}: {len(video)} frames in a minute"
        decoder = av.CodecContext.create("h264", "r")
        sizes = {(p.width, p.height) for v in video for p in decoder.decode(av.Packet(v.data))}
        assert sizes == {(width, height)}, topic


def _holds_every_picture_sent(recorded: np.ndarray, sent: np.ndarray) -> None:
    """Every picture the bus carried between the recording's first and last is in it (by its
    capture time), and the recording spans the minute less its start."""
    assert len(recorded) > 1 and recorded[-1] - recorded[0] > RECORD_S / 2, \
        f"{BIRDSEYE}: {len(recorded)} frames over {np.ptp(recorded):.1f} s"
    between = sent[(sent >= recorded[0]) & (sent <= recorded[-1])]
    i = np.clip(np.searchsorted(recorded, between), 1, len(recorded) - 1)
    found = np.minimum(np.abs(recorded[i] - between), np.abs(recorded[i - 1] - between)) < 1e-6
    assert found.all(), f"{BIRDSEYE}: {np.count_nonzero(~found)} of the {len(between)} " \
                        "pictures the bus carried are not in the recording"


def test_a_minute_is_at_most_thirty_megabytes(minute: Path) -> None:
    samples = [s.received_s for s in read_samples(minute, ["stb/tracker/robot"])]
    minutes = (samples[-1] - samples[0]) / 60
    size_mb = minute.stat().st_size / 1e6
    assert size_mb / minutes <= MB_PER_MINUTE, f"{size_mb:.1f} MB in {minutes:.2f} min"


def test_video_mocap_and_gantry_are_on_one_clock(minute: Path) -> None:
    """Each tracking-camera picture is stamped with its frame's capture time: the gantry's
    estimates and detections carry the capture times of recorded pictures. Every video frame
    has a mocap sample within one frame's time of it (all but the few in the sim's occlusions,
    when the mocap loses the robot for a moment), and a crane state within one frame or one of
    the crane's report periods, whichever is longer."""
    def times(key: str) -> np.ndarray:
        return np.array(sorted(s.measured_s for s in read_samples(minute, [key])))

    estimates, detections = times("stb/gantry/estimate"), times("stb/gantry/detections")
    mocap, crane = times("stb/tracker/robot"), times("stb/gantry/state")

    def nearest(times: np.ndarray, at: np.ndarray) -> np.ndarray:
        i = np.clip(np.searchsorted(times, at), 1, len(times) - 1)
        return np.minimum(np.abs(times[i] - at), np.abs(times[i - 1] - at))

    tracking = np.sort(_stamps(decoded_typed(minute, "/gantry/image")))
    for name, of_frames in (("estimates", estimates), ("detections", detections)):
        inside = of_frames[(of_frames > tracking[0]) & (of_frames < tracking[-1])]
        same_frame = nearest(tracking, inside) < 1e-3
        assert len(inside) > RECORD_S and same_frame.mean() > 0.95, \
            f"{same_frame.mean():.2f} of {len(inside)} {name} on a recorded picture's time"
    crane_period = float(np.median(np.diff(crane)))
    for topic, (_, _, fps) in CHANNELS.items():
        stamps = _stamps(decoded_typed(minute, topic))
        inside = stamps[(stamps > mocap[0] + 1) & (stamps < mocap[-1] - 1)]
        for name, samples, within in (("mocap", mocap, 1 / fps),
                                      ("crane", crane, max(1 / fps, crane_period))):
            near = nearest(samples, inside) <= within
            assert near.mean() >= 0.95, f"{topic}: {near.mean():.3f} near the {name}'s samples"
