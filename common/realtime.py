"""Real-time scheduling for services whose reactions must not wait behind busy processes.

On a shared machine a message's path crosses several processes (tracker → router → PTZ), and
each wake-up can wait behind whatever else runs on the cores — rendering, detection, a
compiler. ``SCHED_FIFO`` lets a waiting service run as soon as its data arrives; measured in
the PTZ benchmark (docs/benchmarks.md), it took the tail of the mocap-to-camera latency from
5–8 ms to under 3 ms. These services sleep between messages, and Linux keeps 5 % of every
second for ordinary processes (``sched_rt_runtime_us``), so a runaway cannot lock a machine.

It needs an ``rtprio`` limit (``ulimit -r``) at least the priority asked for — compose
``ulimits: {rtprio: 10}``, which works for the image's non-root user (``cap_add: [SYS_NICE]``
would not: Docker gives added capabilities to root only) — or ``CAP_SYS_NICE`` (root). Without
either, the service runs with normal scheduling and says so.
"""

from __future__ import annotations

import logging
import os
import resource

log = logging.getLogger(__name__)


def use_realtime_priority(priority: int) -> bool:
    """Put every thread of this process under ``SCHED_FIFO`` at ``priority`` (1–99); threads
    started afterwards inherit it. ``0`` leaves scheduling alone. True if applied; False (and a
    warning that names the fix) if the system does not allow it."""
    if priority == 0:
        return False
    param = os.sched_param(priority)
    try:
        for tid in sorted(int(t) for t in os.listdir("/proc/self/task")):
            try:
                os.sched_setscheduler(tid, os.SCHED_FIFO, param)
            except ProcessLookupError:  # the thread ended meanwhile
                continue
    except PermissionError:
        limit = _rtprio_limit()
        log.warning("realtime_priority %d not applied: not permitted (needs CAP_SYS_NICE or an "
                    "rtprio limit of at least %d, e.g. compose ulimits: {rtprio: %d}; it is %s); "
                    "running with normal scheduling", priority, priority, priority, limit)
        return False
    log.info("real-time scheduling: SCHED_FIFO priority %d", priority)
    return True


def _rtprio_limit() -> str:
    soft, _hard = resource.getrlimit(resource.RLIMIT_RTPRIO)
    return "unlimited" if soft == resource.RLIM_INFINITY else str(soft)
