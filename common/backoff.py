"""Waiting longer after each failure in a row (pure): the first wait, doubled each time up to a
longest one, and back to the first after a success — how every reconnecting client here
(QTM, a camera's video, a PTZ camera, a restarted process) paces itself."""

from __future__ import annotations

from dataclasses import dataclass


def doubled(previous_s: float, longest_s: float) -> float:
    """The wait after ``previous_s``: twice as long, at most ``longest_s``."""
    return min(previous_s * 2, longest_s)


@dataclass
class Backoff:
    first_s: float
    longest_s: float
    wait_s: float = 0.0  # the next wait; the first until a failure doubles it

    def __post_init__(self) -> None:
        self.wait_s = self.wait_s or self.first_s

    def failed(self) -> float:
        """How long to wait now; the next failure in a row waits twice as long."""
        now, self.wait_s = self.wait_s, doubled(self.wait_s, self.longest_s)
        return now

    def succeeded(self) -> None:
        self.wait_s = self.first_s
