"""A camera's video for the recording: the MJPEG stream cut into its JPEGs however TCP splits
it, a camera that is not there, a camera the lab does not have. (From the sim's cameras over
VAPIX into a recording of the whole lab: tests/operator/test_recording_e2e.py.)"""

from __future__ import annotations

import signal
import socket
import threading
import time
from collections.abc import Callable
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from common import keys
from common.bus import Bus
from common.lab_views import CameraConnection
from common.mjpeg import ArrivalStamps, CameraVideo, MjpegParts, VideoError, boundary_of
from tests.conftest import stb_process, wait_for
from tests.ports import free_port

JPEGS = [b"\xff\xd8" + bytes([i]) * (100 + 37 * i) + b"\xff\xd9" for i in range(5)]


def _stream(parts: list[bytes], lengths: bool = True) -> bytes:
    out = b"preamble the parser must skip\r\n"
    for part in parts:
        length = f"Content-Length: {len(part)}\r\n" if lengths else ""
        out += (f"--myboundary\r\nContent-Type: image/jpeg\r\n{length}\r\n".encode() + part
                + b"\r\n")
    return out + b"--myboundary\r\n"


@settings(max_examples=200, deadline=None)
@given(cuts=st.lists(st.integers(min_value=1, max_value=40), max_size=60),
       lengths=st.booleans())
def test_parts_come_out_whole_however_the_stream_is_cut(cuts: list[int], lengths: bool) -> None:
    stream, got, parser, at = _stream(JPEGS, lengths), [], MjpegParts("myboundary"), 0
    for cut in cuts:
        got += parser.feed(stream[at:at + cut])
        at += cut
    got += parser.feed(stream[at:])
    assert got == JPEGS


def test_an_oversized_part_is_dropped_and_the_next_one_kept() -> None:
    parser = MjpegParts("--myboundary", max_part_bytes=200)
    assert parser.feed(_stream([bytes(500), JPEGS[0]])) == [JPEGS[0]]
    assert parser.dropped == 1


def test_what_is_not_a_video_stream_is_named() -> None:
    assert boundary_of('multipart/x-mixed-replace; boundary="myboundary"') == "myboundary"
    with pytest.raises(VideoError, match="not a video stream"):
        boundary_of("text/plain")
    with pytest.raises(VideoError, match="no boundary"):
        boundary_of("multipart/x-mixed-replace")


def test_a_camera_that_is_not_there_is_tried_again_and_ends_nothing() -> None:
    port = free_port()  # nothing listens
    video = CameraVideo("ptz9", CameraConnection(url=f"http://127.0.0.1:{port}"), 5.0,
                        "704x576", lambda *_: None, timeout_s=1.0).start()
    try:
        wait_for(lambda: video.problem, timeout=5)
        assert "ConnectError" in video.problem and video.frames == 0
    finally:
        started = time.monotonic()
        video.stop()
        assert time.monotonic() - started < 3


def test_frames_that_arrive_together_or_after_the_clock_went_back_keep_their_order() -> None:
    readings = iter([10.0, 10.0, 10.0, 9.5, 10.2])
    stamps = ArrivalStamps(clock=lambda: next(readings))
    got = [stamps.next() for _ in range(5)]
    assert got[0] == 10.0 and got[4] == 10.2
    assert all(later > earlier for earlier, later in zip(got, got[1:], strict=False))
    assert got[3] - got[0] == pytest.approx(3 * ArrivalStamps.STEP_S)


def test_a_camera_that_sends_several_frames_in_one_write_gets_them_in_order() -> None:
    """A busy machine reads a camera's backlog: here five JPEGs in one write, each stamped
    after the one before (a recording's video once had two frames with one time stamp)."""
    body = _stream(JPEGS)

    class Camera(BaseHTTPRequestHandler):
        def do_GET(self) -> None:  # noqa: N802 - http.server's name
            self.send_response(200)
            self.send_header("Content-Type", "multipart/x-mixed-replace; boundary=myboundary")
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, *args: object) -> None:
            pass

    server = ThreadingHTTPServer(("127.0.0.1", 0), Camera)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    got: list[tuple[bytes, float]] = []
    video = CameraVideo("ptz9", CameraConnection(url=f"http://127.0.0.1:{server.server_port}"),
                        5.0, "704x576", lambda _, jpeg, at: got.append((jpeg, at)),
                        timeout_s=2.0).start()
    try:
        wait_for(lambda: len(got) >= len(JPEGS), timeout=10, why=lambda: f"{len(got)} frames")
    finally:
        video.stop()
        server.shutdown()
    assert [jpeg for jpeg, _ in got[:len(JPEGS)]] == JPEGS
    times = [at for _, at in got]
    assert all(later > earlier for earlier, later in zip(times, times[1:], strict=False))


def test_stb_record_names_a_camera_it_does_not_know(tmp_path: Path) -> None:
    proc = stb_process("record", str(tmp_path / "x.mcap"), "--video", "ptz7", "--duration", "1",
                       "--connect", f"tcp/127.0.0.1:{free_port()}")
    assert proc.wait(timeout=30) == 2
    assert "no camera ptz7 in [ptz.cameras] (there: ptz1, ptz2)" in proc.stderr.read()


def test_a_recording_says_on_the_bus_that_it_runs(tmp_path: Path, router_endpoint: str,
                                                  make_bus: Callable[..., Bus]) -> None:
    """``stb record`` holds a liveliness token on ``recording/<host>-<pid>`` while it records
    (the PTZ cameras leave their IR-cut filter alone meanwhile), gone when it ends."""
    watcher = make_bus()

    def recordings() -> list[str]:
        return [str(r.ok.key_expr) for r in watcher.session.liveliness().get(
            keys.recording_pattern(watcher.prefix), timeout=1.0) if r.ok is not None]

    proc = stb_process("record", str(tmp_path / "x.mcap"), "--connect", router_endpoint,
                       "--set", "bus.zenoh.listen=[]", "--set", "typed=false")
    try:
        wait_for(lambda: recordings() or proc.poll() is not None, timeout=20, period=0.2)
        assert proc.poll() is None, proc.stderr.read() if proc.stderr else ""
        (key,) = recordings()
        assert key == keys.recording_key(watcher.prefix, f"{socket.gethostname()}-{proc.pid}")
    finally:
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=20)
    wait_for(lambda: not recordings(), timeout=10, period=0.2)
