"""Files another process reads while we write them (common/files.py): a reader sees the old
file or the new one, never part of one; a damaged file is a clear error, not a crash."""

from __future__ import annotations

import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from common.files import write_atomically
from common.heightmap import HeightMap

READER = """
import sys, time
from pathlib import Path
from common.heightmap import HeightMap
path, stop, errors, reads = Path(sys.argv[1]), Path(sys.argv[2]), [], 0
while not stop.exists():
    try:
        HeightMap.load(path)
    except ValueError as err:
        errors.append(str(err))
    reads += 1
    if reads == 1:
        print("reading", flush=True)
print(reads, len(errors), errors[:1])
"""


def _map(value: float) -> HeightMap:
    return HeightMap(np.full((400, 400), value, np.float32), -2000.0, -2000.0, 10.0)


def test_a_height_map_rewritten_while_another_process_reads_it_is_always_whole(
        tmp_path: Path) -> None:
    """The crater file rewritten 40 times while another process loads it in a loop (the sim
    writes it while the gantry and the page read it: once 1,918 of such reads failed)."""
    path, stop = tmp_path / "crater.npz", tmp_path / "stop"
    _map(0.0).save(path)
    reader = subprocess.Popen([sys.executable, "-c", READER, str(path), str(stop)],
                              stdout=subprocess.PIPE, text=True)
    try:
        assert reader.stdout is not None and reader.stdout.readline() == "reading\n"
        for i in range(40):
            _map(float(i)).save(path)
    finally:
        stop.touch()
        out, _ = reader.communicate(timeout=60)
    reads, errors, first = out.split(" ", 2)
    assert int(reads) > 0 and int(errors) == 0, f"{errors} of {reads} reads failed: {first}"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["crater.npz", "stop"], \
        "no temporary file left behind"


def test_a_write_that_fails_leaves_the_old_file_and_no_temporary(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "pose.json"
    write_atomically(path, b"old")

    def full_disk(_fd: int) -> None:  # where a full disk shows: the data reaching it
        raise OSError(28, "No space left on device")

    monkeypatch.setattr("common.files.os.fsync", full_disk)
    with pytest.raises(OSError, match="No space"):
        write_atomically(path, b"new")
    assert path.read_bytes() == b"old" and [p.name for p in tmp_path.iterdir()] == ["pose.json"]


@pytest.mark.parametrize("damage", ["truncated", "empty", "not a zip", "missing array"])
def test_a_damaged_height_map_is_a_clear_error_naming_the_file(tmp_path: Path,
                                                                damage: str) -> None:
    path = tmp_path / "crater.npz"
    _map(1.0).save(path)
    whole = path.read_bytes()
    if damage == "truncated":
        path.write_bytes(whole[: len(whole) // 2])
    elif damage == "empty":
        path.write_bytes(b"")
    elif damage == "not a zip":
        path.write_bytes(b"PK\x03\x04" + b"\x00" * 100)
    else:
        np.savez(path, something_else=np.zeros(3))
    with pytest.raises(ValueError, match="crater.npz"):
        HeightMap.load(path)


def test_threads_writing_one_file_at_once_leave_one_whole_version(tmp_path: Path) -> None:
    path = tmp_path / "users.json"
    versions = [bytes([65 + i]) * 200_000 for i in range(8)]
    threads = [threading.Thread(target=write_atomically, args=(path, v)) for v in versions]
    for t in threads:
        t.start()
    for t in threads:
        t.join(10)
    assert path.read_bytes() in versions
