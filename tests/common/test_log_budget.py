"""The global log budget: a flood of lines from anywhere is held back, errors never are."""

from __future__ import annotations

import logging

from common.node import LogBudget


def _record(level: int = logging.INFO, msg: str = "a collection is already running") -> \
        logging.LogRecord:
    return logging.LogRecord("calib", level, __file__, 1, msg, None, None)


def test_a_flood_is_held_back_counted_and_errors_pass() -> None:
    now = [0.0]
    budget = LogBudget(per_s=20, burst=200, clock=lambda: now[0])
    passed = sum(budget.filter(_record()) for _ in range(4000))  # 4000 lines at one instant
    assert passed == 200
    error = _record(logging.ERROR)
    assert budget.filter(error), "errors always pass"
    assert error.msg.startswith("[3800 log lines held back before this one]")
    assert not budget.filter(_record())
    now[0] = 10.0  # ten seconds later: 20 a second have come back
    record = _record()
    assert budget.filter(record)
    assert record.msg.startswith("[1 log lines held back before this one]")
    assert sum(budget.filter(_record()) for _ in range(1000)) == 199
