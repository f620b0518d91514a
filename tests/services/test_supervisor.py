"""``stb up``'s restarts on a simulated clock: real child processes, the supervisor's ``poll``
given the time. A service that keeps exiting is started again ever later (doubling up to
``restart_max_s``); one that ran ``stable_after_s`` and then exited is started again after
``restart_initial_s``."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from services.supervisor import Child, Supervisor, UpSettings

EXITS = "import sys; sys.exit(3)"  # a service that fails at once
RUNS = "import signal; signal.pause()"  # one that runs until it is killed
POLL_S = 0.01  # the simulated clock's step between polls


class Programs(Supervisor):
    """The supervisor with each child running ``program`` instead of a service."""

    program = EXITS

    def argv(self, child: Child) -> list[str]:
        return [sys.executable, "-c", self.program]


def _starts(supervisor: Programs, child: Child, start_s: float, until_s: float) -> list[float]:
    """Polls from ``start_s`` to ``until_s``; each time a process was started, waits (real
    time) until it has ended before the clock goes on. When each process started."""
    starts = []
    for step in range(round((until_s - start_s) / POLL_S)):
        now = start_s + step * POLL_S
        before = child.process
        supervisor.poll(now)
        if child.process is not None and child.process is not before:
            starts.append(now)
            child.process.wait(10)  # it exits at once
    return starts


def test_a_service_that_keeps_exiting_is_started_ever_later(tmp_path: Path) -> None:
    settings = UpSettings(services=["tracker"], log_dir=tmp_path, restart_initial_s=0.2,
                          restart_max_s=1.0, stable_after_s=10.0)
    supervisor = Programs(settings, None)
    (child,) = supervisor.children
    try:
        starts = _starts(supervisor, child, 0.0, 5.0)
        gaps = [b - a for a, b in zip(starts, starts[1:], strict=False)]
        delays = [0.2, 0.4, 0.8, 1.0, 1.0, 1.0]  # each gap: the delay, and the polls that
        # notice the exit (the next) and reach the restart time (on it, or one after)
        assert len(gaps) >= len(delays)
        assert all(d <= g <= d + 2 * POLL_S + 1e-9 for g, d in zip(gaps, delays, strict=False)), \
            gaps
        assert child.restarts == len(starts) and child.last_exit == 3
        assert (tmp_path / "tracker-main.log").exists()
    finally:
        supervisor.stop_all()


def test_a_service_that_ran_long_enough_is_started_again_soon(tmp_path: Path) -> None:
    settings = UpSettings(services=["tracker"], log_dir=tmp_path, restart_initial_s=0.2,
                          restart_max_s=5.0, stable_after_s=10.0)
    supervisor = Programs(settings, None)
    (child,) = supervisor.children
    try:
        _starts(supervisor, child, 0.0, 3.0)  # at 0, 0.2, 0.6, 1.4 (and a poll): 1.6 s next
        assert child.delay_s == pytest.approx(1.6)
        supervisor.program = RUNS
        supervisor.poll(3.1)
        process = child.process
        assert process is not None and process.poll() is None
        for now in (3.5, 8.0, 15.1):  # running, 12 s of it
            supervisor.poll(now)
            assert child.process is process
        process.kill()
        process.wait(10)
        supervisor.poll(15.1)
        assert child.process is None and child.restart_at == pytest.approx(15.3), \
            "a stable run: restarted after restart_initial_s, not the doubled 3.2 s"
        supervisor.poll(15.29)
        assert child.process is None
        supervisor.poll(15.3)
        assert child.process is not None
    finally:
        supervisor.stop_all()
