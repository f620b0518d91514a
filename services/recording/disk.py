"""The recording's disk: when to stop for it, and room kept to finish the file.

Another process may fill the disk faster than the free-space floor is looked at; the file
could then not be finished (its summary needs room). ``DiskReserve`` holds a few megabytes in
a hidden file next to the recording from its start and gives them back just before the file
is finished, so that a recording stopped for a full disk ends the same however it filled.
"""

from __future__ import annotations

import errno
import io
import logging
import os
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from typing_extensions import Buffer

log = logging.getLogger(__name__)


@dataclass
class DiskWatch:
    """Whether the recording must stop for its disk: less free than ``min_free_mb`` (while the
    file can still be finished), or a write failed (the disk filled up faster)."""

    paths: list[Path]  # the recording's files so far (one, or its parts)
    min_free_mb: float
    write_error: Callable[[], OSError | None]  # the writer's failure, if it had one
    reserve: DiskReserve | None = None
    why: str = ""

    @property
    def folder(self) -> Path:
        return self.paths[0].parent

    def size_mb(self) -> float:
        """The recording's size so far, all its parts."""
        return sum(p.stat().st_size for p in self.paths if p.exists()) / 1e6

    def free_mb(self) -> float:
        try:
            return shutil.disk_usage(self.folder).free / 1e6
        except OSError:
            return float("inf")

    def full(self) -> bool:
        if (error := self.write_error()) is not None:
            self.why = f"cannot write: {error}"
        elif self.reserve is not None and self.reserve.spent is not None:
            self.why = (f"the disk ran full under it ({self.reserve.spent.strerror}; another "
                        f"process filling {self.folder}?)")
        elif (free := self.free_mb()) < self.min_free_mb:
            self.why = (f"{free:.0f} MB free on {self.folder}, less than [record] "
                        f"min_free_mb = {self.min_free_mb:g}")
        return bool(self.why)


class DiskReserve:
    """Room on the disk of ``folder``: ``hold(size_mb)`` takes it at the start (a hidden file,
    its blocks allocated). Files opened with ``open()`` spend it when the disk runs full under
    them (the write that failed is made again into the room given back, and ``spent`` says
    why), and ``release()`` gives it back before the file is finished. Without the room (or
    on a filesystem that cannot allocate ahead) it says so and holds nothing."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        self.path: Path | None = None  # the room held, if any
        self.spent: OSError | None = None  # the write that found the disk full

    def hold(self, size_mb: float) -> None:
        """Take the room (0: none)."""
        if size_mb <= 0:
            return
        self.path = self.folder / f".stb-record-{os.getpid()}.reserve"
        try:
            fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
            try:
                os.posix_fallocate(fd, 0, int(size_mb * 1e6))
            finally:
                os.close(fd)
        except OSError as err:
            log.warning("no room kept to finish the recording (%s: %s); a disk filled by "
                        "another process may leave it unfinished", self.path, err)
            self.release()

    def open(self, path: Path) -> io.BufferedWriter:
        """``path`` opened for writing (truncated), spending the room when the disk is full."""
        return io.BufferedWriter(_SpendingFile(path, self))

    def release(self) -> None:
        """Give the room back (again: nothing)."""
        if self.path is not None:
            self.path.unlink(missing_ok=True)
            self.path = None


class _SpendingFile(io.FileIO):
    """A file whose write, failing for a full disk, releases the reserve and is made again."""

    def __init__(self, path: Path, reserve: DiskReserve) -> None:
        super().__init__(path, "wb")
        self._reserve = reserve

    def write(self, data: Buffer, /) -> int:
        try:
            return super().write(data)
        except OSError as err:
            if err.errno != errno.ENOSPC or self._reserve.path is None:
                raise
            self._reserve.spent = err
            self._reserve.release()
            log.error("the disk ran full (%s); the room kept to finish the recording is "
                      "used, and it stops", err)
            return super().write(data)
