"""Waiting longer after each failure in a row, back to the first after a success."""

from common.backoff import Backoff, doubled


def test_each_failure_in_a_row_waits_twice_as_long_up_to_the_longest() -> None:
    backoff = Backoff(1.0, 10.0)
    assert [backoff.failed() for _ in range(6)] == [1.0, 2.0, 4.0, 8.0, 10.0, 10.0]
    backoff.succeeded()
    assert backoff.failed() == 1.0
    assert doubled(3.0, 5.0) == 5.0 and doubled(2.0, 5.0) == 4.0
