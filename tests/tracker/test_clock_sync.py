"""QTM's capture stamps onto the host's wall clock (``ClockSync``) and the sim's stamps
(``services.sim.clock.Clock``) while the host's wall clock is being slewed against its
monotonic clock — what NTP or chrony does, and what a CI machine did by 2 000–5 000 ppm, so
that every frame looked seconds old after a few minutes and the calibration stopped."""

from __future__ import annotations

import numpy as np
import pytest

from services.sim.clock import Clock
from services.tracker.mocap import ClockSync

RATE_HZ = 100.0
DELAY_S = 0.002  # QTM's capture to the tracker's read


def _ages(sync: ClockSync, seconds: float, slew: float, qtm_drift: float = 0.0,
          stall: tuple[float, float] | None = None,
          step: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
    """Each frame's age as the tracker judges it (wall clock at reading − measured); frames
    captured at QTM's rate, QTM's clock running ``qtm_drift`` fast against the host's monotonic
    clock, the wall clock ``slew`` fast; during ``stall`` (start, length) nothing is read and
    the backlog is read after it, ten times faster than real time; at ``step`` (time,
    seconds) the wall clock steps."""

    def wall_at(monotonic: float) -> float:
        return wall0 + monotonic * (1 + slew) + (step[1] if monotonic >= step[0] > 0 else 0.0)

    wall0 = 1.8e9
    ages, reading_at = [], 0.0
    for n in range(int(seconds * RATE_HZ)):
        captured = n / RATE_HZ  # on the host's monotonic clock
        arrival = captured + DELAY_S
        if stall and stall[0] <= arrival < stall[0] + stall[1]:
            reading_at = max(reading_at, stall[0] + stall[1])
        reading_at = max(arrival, reading_at + (0.1 / RATE_HZ if stall else 0.0))
        wall = wall_at(reading_at)
        measured = sync.measured(captured * (1 + qtm_drift), reading_at, wall)
        true_wall = wall_at(captured)
        ages.append((wall - measured, wall - true_wall))
    return np.array(ages)


def test_a_slewed_wall_clock_leaves_fresh_frames_fresh() -> None:
    ages = _ages(ClockSync(), seconds=300, slew=5e-3, qtm_drift=5e-5)
    judged, true = ages[:, 0], ages[:, 1]
    assert np.max(np.abs(judged - true)) < 0.02  # 300 s at 5 000 ppm: 1.5 s by the old rule


def test_a_stepped_wall_clock_leaves_fresh_frames_fresh() -> None:
    ages = _ages(ClockSync(), seconds=60, slew=0.0, step=(20.005, 5.0))  # 5 s forward
    judged = ages[:, 0]
    assert len(judged) == 6000 and np.max(np.abs(judged)) < 0.02  # the old rule: 5 s after it


def test_a_backlog_after_a_stall_keeps_its_age_under_a_slewed_wall_clock() -> None:
    ages = _ages(ClockSync(), seconds=60, slew=5e-3, stall=(30.0, 2.0))
    judged, true = ages[:, 0], ages[:, 1]
    backlog = true > 0.52  # (judged: less the transport delay floor and the creep)
    assert backlog.sum() > 100  # the stall's frames, read late
    assert np.all(judged[backlog] > 0.5)  # still judged stale: no robot sample from them
    assert np.max(np.abs(judged - true)) < 0.02


def test_the_sims_wall_stamps_follow_a_slewed_wall_clock() -> None:
    now = {"mono": 100.0, "wall": 1.8e9}
    clock = Clock(monotonic=lambda: now["mono"], wall_clock=lambda: now["wall"])
    now["mono"] += 300.0
    now["wall"] += 300.0 * (1 + 5e-3)  # the wall clock slewed
    captured = clock() - 0.04  # a frame exposed 40 ms ago
    assert now["wall"] - clock.wall(captured) == pytest.approx(0.04, abs=1e-6)
