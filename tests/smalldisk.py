"""``stb record`` onto a small disk of its own: a fresh tmpfs in a private mount namespace
(``unshare -m``), optionally filled by another process while it records. For the full-disk
tests and the fault campaign."""

from __future__ import annotations

import shlex
import subprocess
import sys
from pathlib import Path

from mcap.reader import make_reader

from tests.conftest import ROOT

NO_TMPFS = 99
"""The exit code when the tmpfs could not be mounted (no privileges)."""


def record_on_small_disk(lab: Path, folder: Path, *settings: str, size_mb: int = 20,
                         fill_at_bytes: int | None = None) -> tuple[int, str, Path]:
    """``stb record --lab LAB`` into a fresh ``size_mb`` tmpfs under ``folder``; (exit code —
    ``NO_TMPFS`` when it cannot be mounted —, stderr, the file copied out). ``fill_at_bytes``:
    when the recording is this large, another process (``dd``) fills the disk."""
    disk, kept = folder / "disk", folder / "kept"
    disk.mkdir()
    kept.mkdir()
    record = [sys.executable, "-m", "services.cli", "record", str(disk / "run.mcap"), "--lab",
              str(lab), "--duration", "120", "--set", "progress_s=1", "--raw-frames",
              *settings]
    where, run = shlex.quote(str(disk)), shlex.quote(str(disk / "run.mcap"))
    recording = shlex.join(record) if fill_at_bytes is None else (
        # the filler waits (a deadline of 60 s) for the recording to reach its size
        f"{shlex.join(record)} & pid=$!; t=0; while [ $(stat -c %s {run} 2>/dev/null || echo 0)"
        f" -lt {fill_at_bytes} ] && kill -0 $pid && [ $t -lt 1200 ]; do sleep 0.05; t=$((t+1));"
        f" done; dd if=/dev/zero of={shlex.quote(str(disk / 'filler'))} bs=64k 2>/dev/null;"
        f" echo filled at $(stat -c %s {run}) bytes >&2; wait $pid")
    script = (f"mount -t tmpfs -o size={size_mb}m tmpfs {where} || exit {NO_TMPFS}; "
              f"{recording}; code=$?; df -m {where} >&2; ls -a {where} >&2; "
              f"cp {run} {shlex.quote(str(kept))}/; exit $code")
    done = subprocess.run(["unshare", "-m", "sh", "-c", script], cwd=ROOT, capture_output=True,
                          text=True, timeout=180)
    return done.returncode, done.stderr, kept / "run.mcap"


def summary_messages(path: Path) -> int | None:
    """The messages in the file's summary; None when it has none (not finished)."""
    try:
        with open(path, "rb") as f:
            summary = make_reader(f).get_summary()
    except Exception:  # noqa: BLE001 - whatever the reader makes of a broken file: unfinished
        return None
    return None if summary is None or summary.statistics is None \
        else summary.statistics.message_count
