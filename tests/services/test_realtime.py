"""``realtime_priority``: a service process asks for SCHED_FIFO for all of its threads (Zenoh's
included), and runs on with normal scheduling, saying why, where the system does not allow it."""

from __future__ import annotations

import ctypes
import os
import resource
import subprocess
import sys

import pytest

from common.bus import Bus
from tests.conftest import StbProcess, free_port, stb_process, wait_for
from tests.services.test_processes import AliveWatcher, _stop

PR_CAPBSET_DROP, CAP_SYS_NICE = 24, 23


def _router(router_endpoint: str, instance: str, priority: int, **popen: object
            ) -> StbProcess:
    return stb_process("router", "--instance", instance, "--listen",
                       f"tcp/127.0.0.1:{free_port()}", "--set", f'connect=["{router_endpoint}"]',
                       "--set", f"realtime_priority={priority}", **popen)


def _policies(pid: int) -> dict[int, tuple[int, int]]:
    """Each thread's (policy, priority)."""
    out = {}
    for tid in map(int, os.listdir(f"/proc/{pid}/task")):
        try:
            out[tid] = (os.sched_getscheduler(tid), os.sched_getparam(tid).sched_priority)
        except ProcessLookupError:
            continue
    return out


def _unprivileged() -> None:
    """For the child before exec: no CAP_SYS_NICE and no rtprio allowance, as the image's user
    ``stb`` has in a container without ``ulimits: {rtprio: N}``."""
    resource.setrlimit(resource.RLIMIT_RTPRIO, (0, 0))
    ctypes.CDLL(None, use_errno=True).prctl(PR_CAPBSET_DROP, CAP_SYS_NICE, 0, 0, 0)


def _fifo_allowed() -> bool:
    probe = "import os; os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(7))"
    return subprocess.run([sys.executable, "-c", probe], capture_output=True).returncode == 0


# CAP_SYS_NICE, as the tests run here (root). An rtprio limit, the way the containers get it,
# is the kernel's other rule for the same call; raising one needs CAP_SYS_RESOURCE, which this
# machine's root lacks.
@pytest.mark.skipif(not _fifo_allowed(), reason="needs CAP_SYS_NICE or an rtprio limit ≥ 7")
def test_every_thread_of_the_service_runs_under_sched_fifo(
        router_endpoint: str, observer: tuple[Bus, AliveWatcher]) -> None:
    _, alive = observer
    proc = _router(router_endpoint, "rt1", 7)
    try:
        wait_for(lambda: alive.alive("stb/alive/router/rt1"), timeout=10)
        policies = _policies(proc.pid)
        assert len(policies) > 3, "Zenoh's runtime threads, the health thread, the main thread"
        assert set(policies.values()) == {(os.SCHED_FIFO, 7)}, policies
    finally:
        _stop(proc)
    assert "real-time scheduling: SCHED_FIFO priority 7" in proc.stderr.read()


def test_not_permitted_it_says_so_and_runs_with_normal_scheduling(
        router_endpoint: str, observer: tuple[Bus, AliveWatcher]) -> None:
    _, alive = observer
    proc = _router(router_endpoint, "rt2", 7, preexec_fn=_unprivileged)
    try:
        wait_for(lambda: alive.alive("stb/alive/router/rt2"), timeout=10)
        assert {policy for policy, _ in _policies(proc.pid).values()} == {os.SCHED_OTHER}
    finally:
        assert _stop(proc) == 0
    log = proc.stderr.read()
    assert "realtime_priority 7 not applied: not permitted (needs CAP_SYS_NICE" in log
    assert "rtprio limit of at least 7, e.g. compose ulimits: {rtprio: 7}; it is 0)" in log


def test_a_priority_beyond_99_stops_start_up_naming_the_field() -> None:
    proc = stb_process("router", "--set", "realtime_priority=120")
    assert proc.wait(10) == 2
    assert "router.realtime_priority" in proc.stderr.read()
