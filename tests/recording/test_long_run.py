"""A 30-minute run in three parts (tests/recording/long_run.py: the demo lab's message rates)
is reported and replayed as one run, each in a process whose peak memory stays under 500 MB:
both stream through the files."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

from common import keys
from common import messages as m
from common.bus import Bus
from tests.conftest import ROOT, wait_for
from tests.recording.long_run import GANTRY_HZ, write_long_run

MINUTES, PARTS, MEMORY_MB = 30, 3, 500


MEASURE = """
import os, subprocess, sys
proc = subprocess.Popen(sys.argv[1:])
_, status, usage = os.wait4(proc.pid, 0)
print(os.waitstatus_to_exitcode(status), usage.ru_maxrss)
"""
"""Runs a command and prints its exit code and peak resident memory (kB). From a small Python
of its own: a process forked from pytest counts pytest's pages until it has exec'd (676 MB
in CI, for any command)."""


def _peak_mb(*args: str) -> tuple[int, float, str]:
    """Run ``stb ARGS``; (exit code, its peak resident memory in MB, its stderr)."""
    done = subprocess.run([sys.executable, "-c", MEASURE, sys.executable, "-m", "services.cli",
                           *args], cwd=ROOT, capture_output=True, text=True, timeout=540)
    code, peak_kb = done.stdout.strip().splitlines()[-1].split()
    return int(code), int(peak_kb) / 1024, done.stderr


@pytest.fixture(scope="module")
def long_run(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    return write_long_run(tmp_path_factory.mktemp("long") / "run.mcap", MINUTES, PARTS)


@pytest.mark.system
@pytest.mark.timeout(600)
def test_a_thirty_minute_run_in_three_parts_is_reported_in_bounded_memory(
        long_run: list[Path], tmp_path: Path) -> None:
    code, peak, err = _peak_mb("report", *map(str, long_run), "--out", str(tmp_path))
    assert code == 0, err
    assert peak <= MEMORY_MB, f"stb report peaked at {peak:.0f} MB"
    page = (tmp_path / "index.html").read_text()
    assert f"{MINUTES * 60 - 1}" in page or f"{MINUTES * 60}" in page, "the whole run's length"
    assert "40.0" in page, "the crane's 40 mm error, over all three parts"


@pytest.mark.system
@pytest.mark.timeout(600)
def test_a_thirty_minute_run_in_three_parts_is_replayed_in_bounded_memory(
        long_run: list[Path], router_endpoint: str, make_bus: Callable[..., Bus]) -> None:
    states: list[m.CraneState] = []
    make_bus().subscribe(keys.GANTRY_STATE, states.append, latest=False, queue_size=10**6)
    # the tracker's 100 Hz keys are read through but not sent: the bus would take minutes
    code, peak, err = _peak_mb("replay", *map(str, long_run), "--connect", router_endpoint,
                               "--speed", "500", "--exclude", "stb/tracker/**")
    assert code == 0, err
    assert peak <= MEMORY_MB, f"stb replay peaked at {peak:.0f} MB"
    # the replay has put them all; this process's subscriber may still be decoding its queue
    # on a busy machine (36,462 of 45,000 at the replay's end beside the zoom collection)
    expected = MINUTES * 60 * GANTRY_HZ
    wait_for(lambda: len(states) >= expected, timeout=60,
             why=lambda: f"{len(states)} of {expected} crane states")
    assert len(states) == expected, "every crane state of the three parts, once"
