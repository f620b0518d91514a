"""When bytes reached a TCP socket, by the kernel's receive timestamp (SO_TIMESTAMPNS).

The sim's camera server measures when a PTZ command reached the camera. Timing that when its
Python thread gets round to reading the request would add the sim's own scheduling (a thread
waiting for the GIL while another camera renders a snapshot) — time a real camera, which has
hardware of its own, does not add. The kernel stamps each received segment instead; on
loopback that is within about 0.1 ms of the sender's write.
"""

from __future__ import annotations

import contextlib
import io
import socket
import struct
import time
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from _typeshed import WriteableBuffer

SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35)  # Linux; absent elsewhere
_TIMESPEC = struct.Struct("qq")
_ANCILLARY_BYTES = socket.CMSG_SPACE(_TIMESPEC.size)


class StampedReader(io.RawIOBase):
    """Raw reads from a connected socket that remember the receive time of the latest read
    (``arrived_s``, wall clock; the time of the read itself where the kernel gives none:
    ``stamped`` says which)."""

    def __init__(self, sock: socket.socket) -> None:
        super().__init__()
        self._sock = sock
        self.arrived_s = 0.0
        self.stamped = False
        with contextlib.suppress(OSError):  # no kernel stamps: reads are timed when they return
            sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)

    def readable(self) -> bool:
        return True

    def readinto(self, buffer: WriteableBuffer) -> int:
        n, ancillary, _, _ = self._sock.recvmsg_into([buffer], _ANCILLARY_BYTES)
        self.arrived_s, self.stamped = time.time(), False
        for level, kind, data in ancillary:
            if level == socket.SOL_SOCKET and kind == SO_TIMESTAMPNS and len(data) >= 16:
                seconds, nanoseconds = _TIMESPEC.unpack(data[:_TIMESPEC.size])
                self.arrived_s, self.stamped = seconds + nanoseconds * 1e-9, True
        return n
