"""A recording on a disk that fills up: it stops with a clear message and exit 5, its file
readable, and writes nothing more (it once went on for 36 s printing 890 tracebacks)."""

from __future__ import annotations

import errno
import io
import logging
import os
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from common import keys
from common import messages as m
from common.bus import Bus
from services.args import EXIT_DISK
from services.recording.disk import DiskReserve, DiskWatch, allocate_ahead
from services.recording.record import Recorder
from tests.conftest import publish_paced, stb_process, wait_for


def _robot(t: float) -> m.RobotPosition:
    return m.RobotPosition(measured_s=t, label="robot", x_mm=1.0, y_mm=2.0, z_mm=0.0,
                           vx_mm_s=0.0, vy_mm_s=0.0, vz_mm_s=0.0)


def test_below_its_free_space_floor_stb_record_finishes_the_file_and_exits_5(
        make_bus: Callable[..., Bus], router_endpoint: str, tmp_path: Path) -> None:
    """``[record] min_free_mb`` above what the disk has: the recording stops at once, the
    file finished with its summary (the mcap library reads it), exit 5 with why."""
    bus = make_bus()
    out = tmp_path / "run.mcap"
    proc = stb_process("record", str(out), "--connect", router_endpoint, "--duration", "30",
                       "--set", "min_free_mb=1e12", "--set", "typed=false")
    def ended() -> bool:  # the robot's samples, 20 a second, while the recorder runs
        bus.publish(keys.TRACKER_ROBOT, _robot(time.time()))
        return proc.poll() is not None

    wait_for(ended, timeout=30, period=0.05)
    assert proc.wait(timeout=5) == EXIT_DISK
    error = proc.stderr.read()
    assert "stopped:" in error and "min_free_mb" in error and "readable and finished" in error
    with open(out, "rb") as f:
        assert make_reader(f).get_summary() is not None, "finished: the file has its summary"


class FillingFile(io.BytesIO):
    """A file on a disk with ``room`` bytes left: a write beyond fails as the OS says."""

    def __init__(self, room: int) -> None:
        super().__init__()
        self.room = room

    def write(self, data: bytes) -> int:  # type: ignore[override]
        if self.tell() + len(data) > self.room:
            raise OSError(errno.ENOSPC, "No space left on device")
        return super().write(data)


def test_a_disk_that_fills_up_stops_the_writing_with_one_error(
        make_bus: Callable[..., Bus], caplog: pytest.LogCaptureFixture) -> None:
    publisher, recorder_bus = make_bus(), make_bus()
    out = FillingFile(room=300_000)
    recorder = Recorder(recorder_bus.session, "stb", ["stb/**"], out)
    wait_for(lambda: publisher.publish(keys.TRACKER_ROBOT, _robot(time.time())) or
             sum(recorder.stats.samples.values()), why=lambda: "the recorder hears the bus")
    noise = np.random.default_rng(0)
    publish_paced(publisher, keys.GANTRY_FRAME, (  # 12 MB of noise, which zstd cannot shrink
        m.CameraFrame(measured_s=time.time(), camera="tracking", seq=i + 2, width_px=640,
                      height_px=480, encoding="mono8",
                      data=noise.integers(0, 256, 640 * 480, np.uint8).tobytes())
        for i in range(40)), 0.02)
    wait_for(lambda: recorder.write_error is not None, timeout=10)
    wait_for(lambda: recorder.stats.lost > 0)
    recorder.close()  # no exception: nothing more is written
    assert recorder.write_error is not None and recorder.write_error.errno == errno.ENOSPC
    errors = [r for r in caplog.records if r.levelno >= logging.ERROR]
    assert len(errors) == 1 and "cannot write the recording" in errors[0].getMessage()
    assert len(out.getvalue()) <= 300_000


def test_a_disk_full_while_the_file_is_finished_ends_without_an_exception(
        make_bus: Callable[..., Bus]) -> None:
    """Another process filled the disk after the last sample: the summary cannot be written;
    close() says so in ``write_error`` (it once ended ``stb record`` in a traceback)."""
    out = FillingFile(room=10**9)
    recorder = Recorder(make_bus().session, "stb", ["stb/**"], out)
    out.room = out.tell()  # full from here on
    recorder.close()
    assert recorder.write_error is not None and recorder.write_error.errno == errno.ENOSPC


def _allocated(f: io.BufferedWriter) -> tuple[int, int]:
    """(size, bytes allocated on the disk) of an open file."""
    st = os.fstat(f.fileno())
    return st.st_size, st.st_blocks * 512


def test_the_room_is_kept_past_the_files_end_and_given_back(tmp_path: Path) -> None:
    """The room to finish a recording is allocated inside the file, just past what is written,
    and follows it as it grows (no other process can take it); closing gives the rest back."""
    reserve = DiskReserve(1.0)
    with reserve.open(tmp_path / "run.mcap") as f:
        size, allocated = _allocated(f)
        assert size == 0 and allocated >= 1e6, "room from the start, the file still empty"
        for _ in range(50):  # 3.3 MB
            f.write(b"x" * 65536)
            f.flush()
            size, allocated = _allocated(f)
            assert allocated >= size + 0.75e6, (size, allocated)
        assert reserve.spent is None
    kept = (tmp_path / "run.mcap").stat()
    size, allocated = kept.st_size, kept.st_blocks * 512
    assert size == 50 * 65536 and allocated < size + 65536, "the room not used is given back"


def test_a_disk_that_fills_from_outside_stops_the_recording_with_room_to_finish(
        tmp_path: Path) -> None:
    """The room cannot be topped up (ENOSPC): ``spent`` says so, the watch stops the recording;
    what was allocated before is still ahead of the file's end."""
    allowed = [True]

    def allocate(fd: int, offset: int, length: int) -> None:
        if not allowed[0]:
            raise OSError(errno.ENOSPC, "No space left on device")
        allocate_ahead(fd, offset, length)

    reserve = DiskReserve(1.0, allocate=allocate)
    watch = DiskWatch([tmp_path / "run.mcap"], 0.0, lambda: None, reserve)
    with reserve.open(tmp_path / "run.mcap") as f:
        assert not watch.full()
        allowed[0] = False  # another process fills the disk
        while reserve.spent is None:
            f.write(b"x" * 65536)
            f.flush()
        size, allocated = _allocated(f)
        assert allocated >= size + 0.6e6, "about three quarters of the room still ahead"
    assert watch.full() and "the disk ran full under it" in watch.why
