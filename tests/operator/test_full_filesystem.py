"""Recording the demo lab onto a real 20 MB filesystem (a tmpfs of its own, mounted in a
private mount namespace): ``stb record`` ends with a clear message and exit 5, no traceback;
the file is readable by the mcap library up to its last message (finished with its summary
when the free-space floor stopped it first); the lab goes on as before."""

from __future__ import annotations

import shutil
import time
from pathlib import Path

import pytest
from mcap.exceptions import McapError
from mcap.records import Message
from mcap.stream_reader import StreamReader

from common import keys
from common import messages as m
from common.bus import Bus
from services.args import EXIT_DISK
from tests.conftest import client_settings, open_when_up, wait_for
from tests.operator.conftest import LiveLab
from tests.smalldisk import NO_TMPFS, record_on_small_disk, summary_messages

pytestmark = [pytest.mark.system,
              pytest.mark.skipif(shutil.which("unshare") is None, reason="needs unshare(1)")]
SIZE_MB = 20


def _record_on_small_disk(live_lab: LiveLab, folder: Path, *settings: str,
                          fill_at_bytes: int | None = None) -> tuple[int, str, Path]:
    code, err, kept = record_on_small_disk(
        live_lab.lab, folder, "--set", f"height_map={live_lab.crater_file}", *settings,
        size_mb=SIZE_MB, fill_at_bytes=fill_at_bytes)
    if code == NO_TMPFS:
        pytest.skip(f"cannot mount a tmpfs here: {err.strip()}")
    return code, err, kept


def _messages_until_the_end(path: Path) -> int:
    """Messages the mcap library reads from the file's start until it ends or breaks off."""
    count = 0
    with open(path, "rb") as f:
        try:
            for record in StreamReader(f, emit_chunks=False).records:
                count += isinstance(record, Message)
        except (McapError, EOFError, ValueError):
            pass  # where the disk ran full
    return count


def _lab_goes_on(live_lab: LiveLab) -> None:
    session = open_when_up(client_settings(live_lab.endpoint).zenoh)
    bus = Bus(session, client_settings(live_lab.endpoint))
    states: list[m.CraneState] = []
    try:
        bus.subscribe(keys.GANTRY_STATE, states.append, latest=False)
        since = time.time()
        wait_for(lambda: any(s.measured_s > since and s.status == "tracking" for s in states),
                 timeout=10, why=lambda: "gantry: " + str(
                     [(s.status, s.mode, s.mode_reason) for s in states[-3:]]))
    finally:
        bus.close()
        session.close()


def _finished_with(path: Path) -> int:
    """The messages in the file's summary (the mcap library reads it)."""
    count = summary_messages(path)
    assert count is not None, "finished: with a summary"
    return count


def test_a_disk_that_fills_up_with_no_room_kept_ends_the_recording_readable_and_the_lab_goes_on(
        live_lab: LiveLab, tmp_path: Path) -> None:
    code, err, kept = _record_on_small_disk(live_lab, tmp_path, "--set", "min_free_mb=0",
                                            "--set", "reserve_mb=0")
    assert code == EXIT_DISK, err
    assert "Traceback" not in err
    assert "stopped: cannot write" in err and "No space left on device" in err, err
    assert "readable up to its last whole chunk" in err
    assert kept.stat().st_size > (SIZE_MB - 4) * 1e6, "it wrote until the disk was full"
    assert _messages_until_the_end(kept) > 100
    _lab_goes_on(live_lab)


def test_the_free_space_floor_stops_it_first_with_the_file_finished(
        live_lab: LiveLab, tmp_path: Path) -> None:
    code, err, kept = _record_on_small_disk(live_lab, tmp_path, "--set", "min_free_mb=8")
    assert code == EXIT_DISK and "Traceback" not in err, err
    assert "less than [record] min_free_mb = 8" in err and "readable and finished" in err, err
    assert _finished_with(kept) > 100
    _lab_goes_on(live_lab)


def test_a_disk_another_process_fills_ends_the_recording_finished(
        live_lab: LiveLab, tmp_path: Path) -> None:
    """The disk filled from outside faster than the free-space floor is looked at: the room
    kept beside the recording finishes the file (it ended in a traceback, the file rejected
    by the mcap reader); exit 5 like a recording that fills the disk itself."""
    code, err, kept = _record_on_small_disk(live_lab, tmp_path, "--set", "min_free_mb=2",
                                            fill_at_bytes=1_000_000)
    assert code == EXIT_DISK and "Traceback" not in err, err
    assert "filled at" in err and "readable and finished" in err, err
    assert _finished_with(kept) > 100
    available_mb = int(err.split("Mounted on")[1].split()[3])  # `df -m` after the recording
    assert available_mb >= 4, "the room kept in the file and not used is given back"
