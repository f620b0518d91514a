"""A short CPU time slice for latency-critical services (Linux ≥ 6.12, EEVDF scheduler).

Under EEVDF a task that wakes up does not take a busy CPU from the running task until that
task's slice (1.4 ms by default on a 2-core host) is used up — unless the waking task asks for a shorter slice,
which gives it an earlier deadline. On a loaded host the tracker → router → PTZ chain wakes
up four times per mocap frame; with the default slice each wake-up can wait milliseconds
behind snapshot rendering or JSON encoding. ``sched_setattr`` with ``sched_runtime`` set asks
for a custom slice for ordinary (SCHED_OTHER) threads, no privilege needed; threads created
afterwards inherit it. Kernels without custom slices accept and ignore it.
"""

from __future__ import annotations

import ctypes
import os
import platform
import struct

# struct sched_attr, version 0 (48 bytes): size, policy, flags, nice, priority, runtime,
# deadline, period.
_SCHED_ATTR = struct.Struct("IIQiIQQQ")
_SYS_SCHED_SETATTR = {"x86_64": 314, "aarch64": 274}
MIN_SLICE_MS, MAX_SLICE_MS = 0.1, 100.0  # the kernel's bounds for a custom slice


def request_slice(slice_ms: float) -> str | None:
    """Ask for a ``slice_ms`` time slice for every thread of this process (and threads it
    starts later). None if granted, else why not (the process runs on with the default)."""
    if not MIN_SLICE_MS <= slice_ms <= MAX_SLICE_MS:
        raise ValueError(f"slice {slice_ms} ms outside {MIN_SLICE_MS}-{MAX_SLICE_MS} ms")
    number = _SYS_SCHED_SETATTR.get(platform.machine())
    if platform.system() != "Linux" or number is None:
        return f"sched_setattr not known on {platform.system()} {platform.machine()}"
    libc = ctypes.CDLL(None, use_errno=True)
    attr = ctypes.create_string_buffer(
        _SCHED_ATTR.pack(_SCHED_ATTR.size, 0, 0, os.getpriority(os.PRIO_PROCESS, 0), 0,
                         round(slice_ms * 1e6), 0, 0))
    for tid in sorted(int(t) for t in os.listdir("/proc/self/task")):
        if libc.syscall(number, tid, attr, 0) != 0:
            errno = ctypes.get_errno()
            return f"sched_setattr: {os.strerror(errno)}"
    return None


def slice_ms_of(tid: int = 0) -> float:
    """The time slice of a thread (0 = the calling one) in ms: its own, or the default."""
    number = _SYS_SCHED_SETATTR[platform.machine()] + 1  # sched_getattr follows setattr
    libc = ctypes.CDLL(None, use_errno=True)
    attr = ctypes.create_string_buffer(_SCHED_ATTR.size)
    if libc.syscall(number, tid, attr, _SCHED_ATTR.size, 0) != 0:
        raise OSError(ctypes.get_errno(), os.strerror(ctypes.get_errno()))
    return _SCHED_ATTR.unpack(attr.raw)[5] / 1e6
