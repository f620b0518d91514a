"""What the gantry says of itself (modes.py, pure): the crane state's status, its health and
whether it feeds the crane's watchdog."""

from __future__ import annotations

import pytest

from common.crane_registers import ENABLED, FAULT_WATCHDOG, SAFETY_OK
from common.names import GantryMode
from services.gantry.modes import (
    Facts,
    ModeKeeper,
    crane_status,
    health,
    heartbeat_due,
)
from services.gantry.reading import CraneReading

OK = CraneReading(0.0, 0.0, 0.0, 0.0, ENABLED | SAFETY_OK, 0, 0.0, 0.0)
TRIPPED = CraneReading(0.0, 0.0, 0.0, 0.0, SAFETY_OK, FAULT_WATCHDOG, 0.0, 0.0)


@pytest.mark.parametrize(("mode", "reading", "hold", "reacquiring", "status"), [
    ("disarmed", OK, False, False, "idle"),
    ("disarmed", OK, True, True, "idle"),
    ("stopped", OK, False, False, "stopped"),
    ("stopped", TRIPPED, False, False, "stopped"),  # the stop says who and why
    ("armed", OK, False, False, "tracking"),
    ("armed", OK, False, True, "reacquiring"),
    ("armed", OK, True, True, "holding"),
    ("armed", TRIPPED, False, False, "fault"),
    ("disarmed", TRIPPED, False, False, "fault"),
])
def test_the_crane_state_says_what_the_gantry_does(mode: GantryMode, reading: CraneReading,
                                                   hold: bool, reacquiring: bool,
                                                   status: str) -> None:
    assert crane_status(mode, reading, hold=hold, reacquiring=reacquiring) == status


def _keeper(mode: GantryMode) -> ModeKeeper:
    keeper = ModeKeeper(0.0)
    facts = Facts(OK, estimate_age_s=0.0, stale_after_s=1.0)
    if mode == "armed":
        assert keeper.command("arm", "ana", "", 1.0, facts).accepted
    elif mode == "stopped":
        keeper.command("stop", "ana", "lunch", 1.0, facts)
    return keeper


def test_health_while_disarmed_says_whether_it_would_arm() -> None:
    keeper = _keeper("disarmed")
    assert health(keeper, untrusted=None, disagreement="", hold=True, hold_reason="x") == (
        "ok", "disarmed")
    assert health(keeper, untrusted="crane frame off by 80 mm", disagreement="", hold=False,
                  hold_reason="") == ("degraded",
                                      "disarmed; would not arm: crane frame off by 80 mm")


def test_health_when_stopped_names_who_and_why() -> None:
    assert health(_keeper("stopped"), untrusted=None, disagreement="disagree", hold=False,
                  hold_reason="") == ("degraded", "stopped by ana: lunch")


def test_health_while_armed_disagreement_first_then_the_hold() -> None:
    armed = _keeper("armed")
    assert health(armed, untrusted=None, disagreement="fixes 300 mm apart", hold=True,
                  hold_reason="stale") == ("degraded", "fixes 300 mm apart")
    assert health(armed, untrusted=None, disagreement="", hold=True,
                  hold_reason="marker lost") == ("degraded", "marker lost")
    assert health(armed, untrusted=None, disagreement="", hold=False, hold_reason="") == (
        "ok", "")


def test_the_heartbeat_only_while_armed_and_the_loop_alive() -> None:
    assert heartbeat_due(True, 0.0, 25.0)
    assert heartbeat_due(True, 2.5 / 25.0, 25.0), "two and a half periods late is still alive"
    assert not heartbeat_due(True, 2.6 / 25.0, 25.0), "a stuck loop starves the watchdog"
    assert not heartbeat_due(False, 0.0, 25.0)
