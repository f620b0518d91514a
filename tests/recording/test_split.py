"""A long run in parts (``--split-size`` / ``--split-time``): each part is a complete
recording (its summary, the camera pose again, its video starting with a keyframe), and the
parts read, report and replay as one run — every sample once, in order."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import av
import numpy as np
import pytest
from mcap.reader import make_reader

from common import keys
from common import messages as m
from common.bus import Bus
from common.mcap_file import read_run, recorded_keys, run_keys
from services.recording.record import Recorder
from services.recording.split import SplitRule, part_path
from services.recording.typed import LabScene
from services.report.data import read_recording
from services.sim.render import Blob, draw
from tests.conftest import wait_for
from tests.recording.typed import decoded_typed

POSE = m.CameraPose(measured_s=1.0, camera="ptz1", x_mm=1.0, y_mm=2.0, z_mm=3.0, rx_deg=0.0,
                    ry_deg=0.0, rz_deg=0.0, focal_px=782.2, mean_error_px=0.5, passpoints=20)


def test_a_part_is_full_at_its_size_or_its_time() -> None:
    assert not SplitRule().splits and not SplitRule().due(10**12, 0.0, 1e9)
    assert SplitRule(max_bytes=100).due(100, 0.0, 0.0)
    assert not SplitRule(max_bytes=100).due(99, 0.0, 1e9)
    assert SplitRule(max_s=60.0).due(0, 10.0, 70.0) and not SplitRule(max_s=60.0).due(0, 10.0, 69.9)
    assert part_path(Path("/d/run.mcap"), 2) == Path("/d/run-002.mcap")
    assert part_path(Path("run"), 11) == Path("run-011.mcap")


def _robot(i: int, t: float) -> m.RobotPosition:
    return m.RobotPosition(measured_s=t, label="robot", x_mm=float(i), y_mm=0.0, z_mm=0.0,
                           vx_mm_s=0.0, vy_mm_s=0.0, vz_mm_s=0.0)


def test_the_parts_are_complete_recordings_that_read_as_one_run(
        make_bus: Callable[..., Bus], tmp_path: Path) -> None:
    publisher, recorder_bus = make_bus(), make_bus()
    out = tmp_path / "run.mcap"
    paths = [part_path(out, 1)]

    def next_part():  # noqa: ANN202 - the recorder's opener
        paths.append(part_path(out, len(paths) + 1))
        return open(paths[-1], "wb")

    first = open(paths[0], "wb")  # noqa: SIM115 - the recorder's first part, closed below
    t0 = time.time()
    sent = 0
    # the recorder's receive clock runs with the publisher: a camera's 25 frames a second
    recorder = Recorder(recorder_bus.session, "stb", ["stb/**"], first,
                        scene=LabScene(video=True), raw_frames=False,
                        split=SplitRule(max_s=1.0), next_part=next_part,
                        clock=lambda: t0 + 0.04 * sent)
    wait_for(lambda: publisher.publish(keys.CALIB_POSE, POSE, camera="ptz1") and
             recorder.stats.samples["stb/calib/ptz1/pose"], why=lambda: "the pose is recorded")
    rng = np.random.default_rng(0)
    while 0.04 * sent < 3.6:  # three and a half parts of a second each
        now = t0 + 0.04 * sent
        publisher.publish(keys.TRACKER_ROBOT, _robot(sent, now))
        publisher.publish(keys.GANTRY_FRAME, m.CameraFrame(
            measured_s=now, camera="tracking", seq=sent + 1, width_px=160, height_px=120,
            encoding="mono8", data=draw([Blob(80, 60, 5, 5)], 160, 120, rng).tobytes()))
        def recorded(n: int = sent + 1) -> bool:
            return recorder.stats.samples["stb/gantry/camera/frame"] == n

        wait_for(recorded, timeout=10,
                 why=lambda: "the frame is recorded before the clock moves on")
        sent += 1
    wait_for(lambda: recorder.stats.samples["stb/tracker/robot"] == sent, timeout=10,
             why=lambda: f"{recorder.stats.samples['stb/tracker/robot']} of {sent}")
    recorder.close()
    recorder.out.close()
    assert len(paths) >= 3 and recorder.parts == len(paths)
    for path in paths:
        with open(path, "rb") as f:
            assert make_reader(f).get_summary() is not None, f"{path.name} is finished"
        assert recorded_keys(path).get("stb/calib/ptz1/pose", 0) >= 1, f"{path.name}: no pose"
        video = decoded_typed(path, "/gantry/image")
        decoder = av.CodecContext.create("h264", "r")
        frames = [f for v in video for f in decoder.decode(av.Packet(v.data))]
        assert len(frames) == len(video) > 0, f"{path.name}'s video decodes from its start"
    robot = [s for s in read_run(paths) if s.key == "stb/tracker/robot"]
    assert len(robot) == sent, "every sample once"
    assert [s.received_s for s in robot] == sorted(s.received_s for s in robot)
    poses = recorder.stats.samples["stb/calib/ptz1/pose"]  # heard on the bus (not again)
    assert [s.key for s in read_run(paths)].count("stb/calib/ptz1/pose") == poses
    assert run_keys(paths)["stb/tracker/robot"] == sent
    rec = read_recording(paths)
    assert rec.counts["stb/tracker/robot"] == sent and len(rec.robot) == sent
    assert rec.duration_s == pytest.approx(3.6, abs=0.6)
