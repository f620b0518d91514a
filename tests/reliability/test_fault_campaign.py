"""The fault campaign, shortened (a few seconds per fault): ``python -m benchmarks.faults
--short`` as a test. Every goal must hold except those docs/reliability.md reports as not met;
those are checked in their own way here (the memory that grew once is flat when the same fault
comes again; the spoofed frames do not steer the crane out of its workspace)."""

from __future__ import annotations

from pathlib import Path

import pytest

from benchmarks.faults import run, table

# The misses docs/reliability.md explains: the first fuzz and key churn grow some services by
# 20-46 MB once (flat after: the "again" rows hold them to +5 MB), and spoofed frames without
# the robot in them slow the crane down (they take the real frames' place), up to twice the
# baseline's gap and more, though the gate keeps it from following the spoofed spot.
KNOWN_MISSES = {("fuzz", "memory"), ("key churn", "memory"), ("spoofed frames", "gap")}


@pytest.mark.timeout(400)
def test_the_short_campaign_holds_its_goals(tmp_path: Path) -> None:
    rows = run(short=True, per_key=300, churn=1000, folder=tmp_path)
    print(table(rows))
    faults = [r.fault for r in rows]
    for expected in ("fuzz", "fuzz again", "key churn", "key churn again", "decode bombs",
                     "spoofed frames", "spoofed pose", "SIGSTOP gantry 0.3 s",
                     "SIGSTOP gantry 1 s", "SIGSTOP tracker 2 s", "foreign Modbus writer",
                     "SIGKILL gantry", "SIGKILL tracker", "router SIGKILL", "whole campaign"):
        assert expected in faults, f"{expected} did not run"
    unexpected = [(r.fault, miss, r.measured) for r in rows for miss in r.misses
                  if (r.fault, miss) not in KNOWN_MISSES]
    assert not unexpected, unexpected
