"""``stb gantry identify`` against the sim's Modbus crane controller, its tracking camera
looking at a marker that stands still: the crane's configured figures come back within 10 %."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from common.bus import Bus
from services.gantry.commissioning.identify import cycle_tick, tick_after
from services.gantry.commissioning.identify_cli import main
from services.sim.crane import CraneParams, ramp_following_s
from tests.gantry.rig import MARKER_MM, CraneRig, feeding

CONFIGURED = CraneParams(max_speed_mm_s=400.0, max_accel_mm_s2=1500.0, cycle_s=0.25,
                         dead_time_s=0.15, position_time_constant_s=0.06,
                         report_latency_s=0.08, report_jitter_s=0.0,
                         watchdog_s=0.5)
MARKER = np.array([120.0, -60.0])  # stands still below the crane


def _lab(tmp_path: Path, router: str, crane: CraneRig, flat_map: Path) -> Path:
    lab = tmp_path / "lab.toml"
    lab.write_text(f"""
[bus.zenoh]
connect = ["{router}"]
[gantry]
crane_port = {crane.port}
height_map = "{flat_map}"
marker_height_mm = {MARKER_MM}
""")
    return lab


@pytest.mark.system
def test_commissioning_measures_the_crane_that_is_there(
        tmp_path: Path, router_endpoint: str, flat_map: Path, make_bus: Callable[..., Bus],
        capsys) -> None:  # noqa: ANN001
    crane = CraneRig(params=CONFIGURED)
    try:
        lab = _lab(tmp_path, router_endpoint, crane, flat_map)
        with feeding(crane, make_bus(), lambda _t: MARKER, seconds=120.0):
            code = main(["--lab", str(lab), "--box", "300", "--steps", "8", "--yes", "--json"])
        out = capsys.readouterr().out
        assert code == 0, out
        measured = json.loads(out)
    finally:
        crane.close()
    c = CONFIGURED
    expected = {"sampling_s": c.cycle_s, "dead_s": c.dead_time_s,
                "reaction_s": c.dead_time_s + c.cycle_s / 2,
                "report_age_s": c.report_latency_s, "top_speed_mm_s": c.max_speed_mm_s,
                "accel_mm_s2": c.max_accel_mm_s2}
    for name, value in expected.items():
        assert measured[name]["median"] == pytest.approx(value, rel=0.10), (name, measured)
    assert measured["report_spread_s"]["median"] < 0.015, "no jitter: the camera's noise only"
    # setpoint taken → crane follows, as the model follows the same ramp on a simulated
    # clock; here the writes and frames go on real time (measured: 0.03 s more)
    assert measured["following_s"]["median"] == pytest.approx(ramp_following_s(c), abs=0.045)


def test_it_will_not_move_an_enabled_crane_nor_without_a_marker(
        tmp_path: Path, router_endpoint: str, flat_map: Path, capsys) -> None:  # noqa: ANN001
    crane = CraneRig(params=CraneParams(watchdog_s=60.0))  # whoever enabled it keeps it so
    try:
        lab = _lab(tmp_path, router_endpoint, crane, flat_map)
        assert main(["--lab", str(lab), "--yes"]) == 3
        assert "no marker" in capsys.readouterr().err
        crane.at_the_panel(1)  # enabled: someone else drives it
        assert main(["--lab", str(lab), "--yes"]) == 1
        assert "the crane is enabled" in capsys.readouterr().err
    finally:
        crane.close()


def test_the_controllers_tick_is_the_earliest_sighting_not_the_last() -> None:
    """Each sighting of the setpoint counter going up is late — by part of a poll, and on a busy
    machine by whatever held the poller up — never early: the tick is the earliest phase."""
    rng = np.random.default_rng(3)
    period, tick = 0.25, 100.013
    ticks = tick + period * np.arange(20)
    late = rng.uniform(0.0, 0.005, 20)
    late[[5, 12, 19]] = [0.04, 0.06, 0.05]  # the poller held up, the last sighting among them
    seen = ticks + late
    found = cycle_tick(seen, period, seen[-1])
    assert abs((found - tick + period / 2) % period - period / 2) <= 0.005
    assert abs((seen[-1] - tick + period / 2) % period - period / 2) > 0.04  # what it used


def test_the_tick_after_a_write_is_on_the_grid_not_the_late_sighting() -> None:
    """The dead time counts from the tick that took the step: a poller held up after the write
    sees the counter late; the grid of the ticks around it does not."""
    period, tick = 0.25, 50.0
    ticks = tick + period * np.arange(24)
    seen = ticks + 0.003
    seen[9] += 0.03  # the first sighting after the write, late
    written = ticks[8] + 0.1
    found = tick_after(seen, period, written)
    assert found is not None and abs(found - ticks[9]) <= 0.005
    assert tick_after(seen[:0], period, written) is None
