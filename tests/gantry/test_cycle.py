"""CycleSync: the gantry ticks a fixed time after the crane controller reports, whatever the
phase between their clocks; it runs free until it has seen a report change."""

from __future__ import annotations

import numpy as np
import pytest

from common.errors import ConfigError
from common.settings import load_settings
from services.gantry.cycle import CycleSync, dithered_period_s
from services.gantry.settings import GantrySettings

PERIOD, POLL = 0.25, 0.025


def _ticks(sync: CycleSync, report_phase: float, start: float, seconds: float,
           moves: tuple[float, float] = (0.0, np.inf)) -> list[float]:
    """Poll a controller that reports at ``report_phase`` + k · PERIOD, its position changing
    at every report while the crane ``moves`` (from, until); the poll times the sync ticked."""
    ticks = []
    for t in start + POLL * np.arange(int(seconds / POLL)):
        moved_until = min(max(t, moves[0]), moves[1])
        reports = np.floor((moved_until - report_phase) / PERIOD)  # reports of a move by t
        sync.observe(float(t), (float(reports), 0.0))
        if sync.due(float(t)):
            ticks.append(float(t))
    return ticks


@pytest.mark.parametrize("report_phase", [0.005, 0.08, 0.13, 0.2, 0.249])
def test_ticks_settle_at_the_offset_after_each_report(report_phase: float) -> None:
    sync = CycleSync(PERIOD, offset_s=0.1)
    ticks = _ticks(sync, report_phase, start=0.2, seconds=10.0)
    ages = [(t - report_phase) % PERIOD for t in ticks[4:]]
    assert min(ages) >= 0.1 - POLL / 2 - 1e-9 and max(ages) <= 0.1 + POLL + 1e-9, ages
    assert np.diff(ticks).min() >= PERIOD / 2 and np.diff(ticks).max() <= 1.5 * PERIOD + POLL
    assert len(ticks) == pytest.approx(10.0 / PERIOD, abs=2)
    assert sync.report_phase_s == pytest.approx(report_phase, abs=POLL / 2 + 1e-9)


def test_runs_free_at_the_period_until_the_crane_moves_and_keeps_the_phase_after() -> None:
    sync = CycleSync(PERIOD, offset_s=0.1)
    moves = (5.0, 8.0)
    still = _ticks(sync, 0.2, start=0.0, seconds=5.0, moves=moves)
    assert sync.report_phase_s is None
    assert np.allclose(np.diff(still), PERIOD), "free-running: no drift at poll granularity"
    _ticks(sync, 0.2, start=5.0, seconds=3.0, moves=moves)
    learnt = sync.report_phase_s
    assert learnt == pytest.approx(0.2, abs=POLL / 2 + 1e-9)
    after = _ticks(sync, 0.2, start=8.0, seconds=3.0, moves=moves)
    assert sync.report_phase_s == learnt
    assert all(abs((t - 0.2) % PERIOD - 0.1) <= POLL + 1e-9 for t in after[1:])


@pytest.mark.parametrize("seed", range(6))
def test_dithered_polls_find_the_phase_within_milliseconds(seed: int) -> None:
    """Polls a random 50-150 % of a period apart: the brackets around each change differ,
    and where they overlap pins the report's phase to a few milliseconds, where polls at a
    fixed phase to the cycle leave it half a poll off."""
    rng = np.random.default_rng(seed)
    report_phase = float(rng.uniform(0, PERIOD))
    sync, t = CycleSync(PERIOD), float(rng.uniform(0, 1))
    while t < 3.0:
        sync.observe(t, (float(np.floor((t - report_phase) / PERIOD)), 0.0))
        t += dithered_period_s(POLL, float(rng.random()))
    learnt = sync.report_phase_s
    assert learnt is not None
    off = (learnt - report_phase + PERIOD / 2) % PERIOD - PERIOD / 2
    assert abs(off) <= 0.004, off


def test_follows_a_controller_whose_cycle_moves() -> None:
    sync = CycleSync(PERIOD, offset_s=0.05)
    _ticks(sync, 0.03, start=0.0, seconds=5.0)
    ticks = _ticks(sync, 0.17, start=5.0, seconds=5.0)  # the controller restarted
    assert all(abs((t - 0.17) % PERIOD - 0.05) <= POLL + 1e-9 for t in ticks[-8:])


def test_an_offset_outside_the_period_is_refused() -> None:
    with pytest.raises(ValueError, match="offset_s"):
        CycleSync(PERIOD, offset_s=0.25)


@pytest.mark.parametrize(("overrides", "field"), [
    ({"after_report_s": 0.25}, "gantry.after_report_s"),
    ({"control_hz": 10, "after_report_s": 0.1}, "gantry.after_report_s"),
    ({"poll_hz": 6}, "gantry.poll_hz"),
])
def test_timing_settings_that_cannot_work_name_the_field(overrides: dict, field: str) -> None:
    with pytest.raises(ConfigError, match=field.replace(".", r"\.")):
        load_settings(GantrySettings, overrides=overrides, environ={})


@pytest.mark.parametrize("poll_phase_s", [0.004, 0.013, 0.021])
@pytest.mark.parametrize("after_report_s", [0.03, 0.15])
def test_the_loop_writes_setpoints_a_fixed_time_after_the_controller_reports(
        after_report_s: float, poll_phase_s: float) -> None:
    """The gantry's loop over the sim's crane model on the simulated clock (sim_rig): each
    setpoint is written ``after_report_s`` after the report it answers, within a poll, whatever
    the phase of the gantry's polls against the controller's cycle. Over Modbus on real time:
    tests/gantry/test_service.py (a system test)."""
    from tests.gantry.sim_rig import POLL_S, SimGantry, rig_settings

    start = np.array([-300.0, 0.0])
    gantry = SimGantry(rig_settings(after_report_s=after_report_s),
                       lambda t: start + [120.0 * t, 0.0], poll_phase_s=poll_phase_s)
    ages: list[float] = []  # of the controller's report when a setpoint is written
    write = gantry.crane.write_setpoint

    def recording(x_mm: float, y_mm: float) -> None:
        gantry.model.advance_to(gantry.now)
        ages.append(gantry.now - gantry.model.published_s)
        write(x_mm, y_mm)

    gantry.crane.write_setpoint = recording  # type: ignore[method-assign]
    gantry.arm_when_in_view()
    assert gantry.run(10, lambda: len(ages) >= 24), "setpoints stopped"
    settled = np.array(ages[-16:])
    assert np.all((settled >= after_report_s - 1e-9) & (settled < after_report_s + POLL_S)), \
        settled
