"""The recording's disk: when to stop for it, and room kept to finish the file.

Another process may fill the disk faster than the free-space floor is looked at; the file
could then not be finished (its summary needs room). ``DiskReserve`` keeps a few megabytes
allocated inside the file, just past its end, from its start: when the disk fills from outside
the recording stops and is finished in that room, so that a recording stopped for a full disk
ends the same however it filled. (A hidden file of room beside the recording, given back to
finish it, was taken by the process that filled the disk as soon as it was given back.)
"""

from __future__ import annotations

import ctypes
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


_FALLOC_FL_KEEP_SIZE = 1  # linux/falloc.h: blocks allocated, the file's size unchanged
_libc = ctypes.CDLL(None, use_errno=True)


def allocate_ahead(fd: int, offset: int, length: int) -> None:
    """Blocks for ``[offset, offset + length)`` of an open file, its size unchanged (Linux
    ``fallocate(2)`` with ``FALLOC_FL_KEEP_SIZE``); writes there need no more room on the disk.
    OSError when it cannot (ENOSPC: the disk is full; EOPNOTSUPP: not on this filesystem)."""
    fallocate = getattr(_libc, "fallocate", None)
    if fallocate is None:
        raise OSError(errno.EOPNOTSUPP, "fallocate(2) is not available here")
    if fallocate(ctypes.c_int(fd), ctypes.c_int(_FALLOC_FL_KEEP_SIZE),
                 ctypes.c_longlong(offset), ctypes.c_longlong(length)) != 0:
        code = ctypes.get_errno()
        raise OSError(code, os.strerror(code))


class DiskReserve:
    """Room kept inside each file it opens, just past what is written: ``size_mb`` of blocks
    allocated ahead (``allocate_ahead``) and topped up as the file grows, so that the file can
    always be finished — the room belongs to the file, no other process can take it. When the
    room cannot be topped up for a full disk, ``spent`` says why (about three quarters of it
    are still ahead, for the summary); closing the file gives back what it did not use. With
    ``size_mb = 0``, or on a filesystem that cannot allocate ahead (said once), it keeps none."""

    def __init__(self, size_mb: float,
                 allocate: Callable[[int, int, int], None] = allocate_ahead) -> None:
        self.size = int(size_mb * 1e6)
        self.allocate = allocate
        self.spent: OSError | None = None  # the top-up that found the disk full

    def open(self, path: Path) -> io.BufferedWriter:
        """``path`` opened for writing (truncated), with the room ahead of its end."""
        return io.BufferedWriter(_FileWithRoom(path, self))

    def keep_ahead(self, fd: int, offset: int) -> bool:
        """Allocate the room from ``offset``; False when it could not (and then no more)."""
        if self.size <= 0 or self.spent is not None:
            return False
        try:
            self.allocate(fd, offset, self.size)
        except OSError as err:
            if err.errno == errno.ENOSPC:
                self.spent = err
                log.error("the disk ran full (%s); the room kept to finish the recording is "
                          "used, and it stops", err)
            else:
                log.warning("no room kept to finish the recording (%s); a disk filled by "
                            "another process may leave it unfinished", err)
            self.size = 0
            return False
        return True


class _FileWithRoom(io.FileIO):
    """A file written at its end with ``reserve``'s room allocated just past it."""

    def __init__(self, path: Path, reserve: DiskReserve) -> None:
        super().__init__(path, "wb")
        self._reserve = reserve
        self._room_to = 0  # the room is allocated up to here
        self._top_up()

    def _top_up(self) -> None:
        end = self.tell()
        if self._room_to - end < self._reserve.size * 3 // 4 \
                and self._reserve.keep_ahead(self.fileno(), end):
            self._room_to = end + self._reserve.size

    def write(self, data: Buffer, /) -> int:
        written = super().write(data)
        self._top_up()
        return written

    def close(self) -> None:
        if not self.closed and self._room_to:
            try:  # the room not used goes back to the disk: blocks past the end are freed
                os.ftruncate(self.fileno(), os.fstat(self.fileno()).st_size)
            except OSError as err:
                log.warning("the room kept past the recording's end is not given back: %s", err)
        super().close()
