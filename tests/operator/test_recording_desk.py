"""The page's recording desk counts a recording's time from when ``stb record`` has started up
and opened its file, not from when it was launched: on a busy host the recorder's start-up
(its imports) took over 20 s in a CI run, and a stop after the page's 20 s ended it before it
had recorded anything. Here a stand-in recorder opens its file only when told to (through a
FIFO) and ends at the desk's SIGINT."""

from __future__ import annotations

import contextlib
import os
import sys
from pathlib import Path

from services.web.recordings import RecordingDesk
from tests.conftest import wait_for

# reads one byte from the FIFO given first, opens its file (the path after), waits for SIGINT
STAND_IN = (
    "import pathlib, signal, sys\n"
    "with open(sys.argv[1], 'rb') as go:\n"
    "    go.read(1)\n"
    "pathlib.Path(sys.argv[2]).write_bytes(b'')\n"
    "try:\n"
    "    signal.pause()\n"
    "except KeyboardInterrupt:\n"
    "    pass\n")


def _tell(fifo: Path) -> bool:
    """One byte into the FIFO once the stand-in has it open for reading."""
    with contextlib.suppress(OSError):  # ENXIO: no reader yet
        fd = os.open(fifo, os.O_WRONLY | os.O_NONBLOCK)
        try:
            os.write(fd, b"x")
        finally:
            os.close(fd)
        return True
    return False


def test_the_recording_counts_from_when_its_file_is_open(tmp_path: Path) -> None:
    go = tmp_path / "go"
    os.mkfifo(go)
    desk = RecordingDesk(tmp_path / "recordings", {},
                         recorder=[sys.executable, "-c", STAND_IN, str(go)])
    name = desk.start("olga")["name"]
    current = desk.view()["current"]
    assert current["name"] == name and current["starting"] and current["elapsed_s"] == 0.0
    wait_for(lambda: _tell(go), timeout=30)
    recording = wait_for(lambda: (c := desk.view()["current"]) and not c["starting"] and c,
                         timeout=30, why=lambda: str(desk.view()))
    assert 0.0 <= recording["elapsed_s"] < 5.0
    assert desk.stop("olga") == {"name": name, "recording": False}
    assert desk.view()["current"] is None
    # its empty file makes no report, and the page says so
    wait_for(lambda: desk.view()["past"][0]["state"].startswith("no report"), timeout=60,
             period=0.2, why=lambda: str(desk.view()))
