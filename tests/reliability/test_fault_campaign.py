"""The fault campaign, shortened (a few seconds per fault): ``python -m benchmarks.faults
--short`` as a test, on loopback. Every goal must hold (docs/reliability.md)."""

from __future__ import annotations

from pathlib import Path

import pytest

from benchmarks.faults import STEPS, run, table


@pytest.mark.system
@pytest.mark.timeout(600)
def test_the_short_campaign_holds_its_goals(tmp_path: Path) -> None:
    steps = [step for step in STEPS if step != "quiet"]  # the control window: the docs' run
    rows = run(short=True, per_key=300, churn=1000, folder=tmp_path, only=steps)
    print(table(rows))
    faults = [r.fault for r in rows]
    for expected in ("fuzz", "fuzz again", "key churn", "key churn again", "decode bombs",
                     "spoofed frames", "spoofed pose", "SIGSTOP gantry 0.3 s",
                     "SIGSTOP gantry 1 s", "SIGSTOP tracker 2 s", "foreign Modbus writer",
                     "SIGKILL gantry", "SIGKILL tracker", "router SIGKILL",
                     "200 event streams at once", "drifting spoofed frames",
                     "calibration-mode flood", "command flood", "foreign Origin at stb foxglove",
                     "crater file rewritten while read", "wrong sign-ins",
                     "viewer sign-ins", "X-Forwarded-For from loopback", "foreign Host",
                     "huge bodies", "report folder's link out",
                     "page move in calibration mode", "disk filled from outside",
                     "crater imports", "camera reboot", "whole campaign"):
        assert expected in faults, f"{expected} did not run"
    missed = [(r.fault, r.misses, r.measured) for r in rows if not r.held]
    assert not missed, missed
