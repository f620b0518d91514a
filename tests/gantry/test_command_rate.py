"""The gantry's command rate (services/gantry/command_rate.py) on an injected clock, and a
flood of commands against the live service and a CraneRig (tests/gantry/rig.py)."""

from __future__ import annotations

import time

import pytest

from common import keys
from common import messages as m
from services.gantry.command_rate import MAX_SENDERS, CommandRate
from tests.conftest import wait_for


def test_a_sender_gets_its_burst_then_its_rate() -> None:
    rate = CommandRate(per_s=2.0, burst=5)
    taken = [rate.admit("eve", 0.0).admitted for _ in range(8)]
    assert taken == [True] * 5 + [False] * 3
    assert not rate.admit("eve", 0.4).admitted  # 0.8 of a token
    assert rate.admit("eve", 0.5).admitted  # one token back after 1/per_s
    assert rate.admit("olga", 0.5).admitted, "another sender has its own bucket"


def test_the_first_refusal_of_a_flood_is_reported_once() -> None:
    rate = CommandRate(per_s=2.0, burst=2)
    refusals = [a for a in (rate.admit("eve", 0.0) for _ in range(10)) if not a.admitted]
    assert [a.report for a in refusals] == [True] + [False] * 7
    assert refusals[-1].refused_in_flood == 8
    rate.admit("eve", 10.0)  # its bucket full again: the flood is over
    flood = [rate.admit("eve", 10.0) for _ in range(3)]
    assert [a.report for a in flood if not a.admitted] == [True, False]


def test_a_long_flood_is_reported_once() -> None:
    """One sender flooding for 10 s at 100 a second: the flood is over only when the sender's
    own bucket is full again."""
    rate = CommandRate(per_s=2.0, burst=5)
    reports = sum(rate.admit("flood", i / 100).report for i in range(1000))
    assert reports == 1
    assert not rate.admit("flood", 10.0 + 3.0).report, "3 s quiet: its bucket is full, taken"
    assert sum(rate.admit("flood", 13.0 + i / 100).report for i in range(100)) == 1, \
        "a new flood after the quiet is reported again"


def test_a_stop_is_always_taken_and_spends_tokens() -> None:
    rate = CommandRate(per_s=1.0, burst=2)
    assert all(rate.admit("eve", 0.0, always=True).admitted for _ in range(50))
    assert not rate.admit("eve", 0.0).admitted, "the stops used the sender's tokens"


def test_no_sender_spends_another_senders_tokens() -> None:
    rate = CommandRate(per_s=2.0, burst=5)
    for i in range(1000):
        while rate.admit(f"name{i}", 0.0).admitted:
            pass
    assert rate.admit("olga", 0.0).admitted, "a thousand floods later, olga's bucket is full"
    assert len(rate._senders) <= MAX_SENDERS  # memory bounded under a flood of senders


@pytest.mark.timeout(60)
@pytest.mark.parametrize("rig", [{"command_burst": 5, "command_per_s": 2.0}], indirect=True)
def test_a_flood_under_a_thousand_names_is_one_senders_flood(
        rig: dict, caplog: pytest.LogCaptureFixture) -> None:
    """3,000 disarms from one bus identity under 1,000 names in about a second: at most its
    burst and rate are carried out, the rest answered "too many" for that identity, logged
    once; an operator with another identity is obeyed at once, every time."""
    operator, world = rig["operator"], rig["world"]
    wait_for(lambda: operator.states, timeout=10)
    start = time.monotonic()
    for i in range(3000):
        world.publish(keys.GANTRY_COMMAND, m.GantryCommand(
            measured_s=time.time(), command="disarm", operator=f"name{i % 1000}",
            id=f"flood-{i}"), sender="intruder")
        if i % 1000 == 0:
            reply = operator.send("stop")  # meanwhile
            assert reply.accepted and "too many" not in reply.detail
    seconds = time.monotonic() - start
    flood = lambda: [r for r in operator.replies if r.id.startswith("flood-")]  # noqa: E731
    wait_for(lambda: len(flood()) >= 100, timeout=10, why=lambda: f"{len(flood())} replies")
    taken = [r for r in flood() if "too many" not in r.detail]
    bound = 5 + 2 * (seconds + 1.0)
    assert len(taken) <= bound, f"{len(taken)} of 3000 carried out in {seconds:.1f} s"
    refused = [r for r in flood() if "too many" in r.detail]
    assert refused and all("too many commands from 'intruder'" in r.detail for r in refused)
    assert sum("too many commands from 'intruder'" in r.message for r in caplog.records) == 1
    for command in ("reset", "disarm", "stop"):
        reply = operator.send(command)  # the test operator's own bucket
        assert reply.accepted, reply.detail


@pytest.mark.timeout(60)
@pytest.mark.parametrize("rig", [{"command_burst": 2, "command_per_s": 0.5}], indirect=True)
def test_the_page_s_users_are_limited_each_on_their_own(rig: dict) -> None:
    """The page (a delegate: it signs in its own users) floods for one user; another user of
    the page is still obeyed."""
    operator, world = rig["operator"], rig["world"]
    wait_for(lambda: operator.states, timeout=10)
    for i in range(20):
        world.publish(keys.GANTRY_COMMAND, m.GantryCommand(
            measured_s=time.time(), command="stop", operator="eve (web 10.0.0.9)",
            id=f"eve-{i}"), sender="web")
    world.publish(keys.GANTRY_COMMAND, m.GantryCommand(
        measured_s=time.time(), command="disarm", operator="eve (web 10.0.0.9)",
        id="eve-disarm"), sender="web")
    world.publish(keys.GANTRY_COMMAND, m.GantryCommand(
        measured_s=time.time(), command="reset", operator="olga (web 10.0.0.5)",
        id="olga-reset"), sender="web")
    reply = lambda i: next((r for r in operator.replies if r.id == i), None)  # noqa: E731
    refused, olga = wait_for(lambda: reply("eve-disarm")), wait_for(lambda: reply("olga-reset"))
    assert not refused.accepted and "too many commands from 'web/eve (web 10.0.0.9)'" in \
        refused.detail
    assert olga.accepted, olga.detail
