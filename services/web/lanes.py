"""The page's work in separate lanes, so that no kind of request waits behind another.

A password check (argon2: 64 MiB and about 0.2 s of a core each) runs in a lane of its own
with ``at_once`` threads; requests that need one queue for it without holding a thread, and
with ``queued`` in the lane the next is refused at once (``Busy``: 503 with ``Retry-After``).
Commands (the gantry's Stop among them) have a lane of their own too, so neither a flood of
sign-ins nor many slow state requests can delay a Stop: a fault campaign once held a
signed-in operator's Stop for 16.6 s behind 200 wrong passwords, which filled every thread
the page had.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

import anyio

T = TypeVar("T")

PASSWORDS_AT_ONCE = 1
"""One check at a time leaves the other core of a two-core PC to everything else."""
PASSWORDS_QUEUED = 16
"""Checks in the lane at most (about 3.5 s of argon2 at one at a time); more are refused."""
COMMANDS_AT_ONCE = 8
"""Commands carried out at once (each waits up to a few seconds for the gantry's answer)."""


class Busy(Exception):
    """Too many requests wait for this lane: answer 503 and ask to come back."""

    def __init__(self, detail: str, retry_after_s: float) -> None:
        super().__init__(detail)
        self.detail, self.retry_after_s = detail, retry_after_s


class Lane:
    """Blocking work on threads of its own: at most ``at_once`` at a time, at most
    ``queued`` in the lane, running ones included (None: no bound)."""

    def __init__(self, name: str, at_once: int, queued: int | None = None,
                 retry_after_s: float = 2.0) -> None:
        self.name, self.queued, self.retry_after_s = name, queued, retry_after_s
        self._limiter = anyio.CapacityLimiter(at_once)
        self.waiting = 0

    async def run(self, work: Callable[..., T], *args: object) -> T:
        if self.queued is not None and self.waiting >= self.queued:
            raise Busy(f"too many {self.name} at once: try again in a moment",
                       self.retry_after_s)
        self.waiting += 1
        try:
            return await anyio.to_thread.run_sync(work, *args, limiter=self._limiter)
        finally:
            self.waiting -= 1


def password_lane() -> Lane:
    return Lane("password checks", PASSWORDS_AT_ONCE, PASSWORDS_QUEUED)


def command_lane() -> Lane:
    return Lane("commands", COMMANDS_AT_ONCE)
